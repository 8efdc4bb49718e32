"""Canonical encoding of TRACE messages: the exact bytes that digests are taken over.

The canonical bytes of a layer message are compact JSON (UTF-8, no whitespace) of the form
``{"cycle":C,"t_ns":T,<the record's fields in schema order>}``. A seal is the JSON of the
``Seal`` model in the same style. Whatever re-encodes a message later (the warm and cold tiers)
must give back these bytes exactly; a reader never re-serialises to verify.
"""

from __future__ import annotations

from typing import Any

import orjson

from trace_runtime.records import Seal, _Record


def encode_layer(cycle: int, t_ns: int, record: _Record) -> bytes:
    """Canonical bytes of one layer record stamped with its cycle and time."""
    # The serializer itself: the bytes of ``model_dump_json(by_alias=True)`` without the
    # str round trip (a writer's hot path: four records per cycle).
    body = record.__pydantic_serializer__.to_json(record, by_alias=True)
    stamp = b'{"cycle":%d,"t_ns":%d' % (cycle, t_ns)
    if body == b"{}":
        return stamp + b"}"
    return b"".join((stamp, b",", memoryview(body)[1:]))


def encode_seal(seal: Seal) -> bytes:
    """Canonical bytes of a seal."""
    return seal.model_dump_json(by_alias=True).encode()


def encode_seal_fields(
    cycle: int, t_ns: int, digests: dict[str, str], prev: str, dropped: int
) -> bytes:
    """Canonical bytes of a seal built from its fields, without a model (the writer's hot
    path). Byte-identical to ``encode_seal(Seal(...))``; a test holds the two together."""
    inner = b",".join(b'"%s":"%s"' % (t.encode(), d.encode()) for t, d in digests.items())
    return b'{"cycle":%d,"t_ns":%d,"digests":{%s},"prev":"%s","dropped":%d}' % (
        cycle,
        t_ns,
        inner,
        prev.encode(),
        dropped,
    )


def encode_json(value: Any) -> bytes:
    """Compact JSON for free-form payloads (sensor readings, metadata)."""
    return orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY)


def decode_json(data: bytes) -> Any:
    """Parse a JSON payload."""
    return orjson.loads(data)
