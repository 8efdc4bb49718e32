"""The byte coding of a block's streams and columns: integers as little-endian byte planes
(delta-coded or not), small integers at the narrowest width, and each column codec's decoder.

The encoder picks a column's codec (``encode``); the decoding of every codec lives here, with
the plans that map a shape's slots to the columns they read, so that a whole decode
(``decode``) and a partial one (``seek``) read the columns alike.
"""

from __future__ import annotations

import sys
from array import array
from collections.abc import Sequence
from itertools import accumulate, repeat
from operator import sub, truediv
from typing import Any

import orjson

from trace_runtime.errors import ColdFormatError
from trace_runtime.tier_formats.cold.format import (
    BOOL,
    CONST,
    DEC,
    DIGEST,
    F64,
    INT,
    JSON,
    LENGTHS,
    NULLABLE,
    SENSORS,
    STR,
    ColumnKey,
)
from trace_runtime.tier_formats.cold.sensors import DERIVED
from trace_runtime.tier_formats.shapes import Shape

SCALES = tuple(10.0**k for k in range(23))
"""Decimal columns: values times ``SCALES[k]`` are the integers stored."""

# Width codes in the format -> array typecodes of exactly 1, 2 and 4 bytes on this platform.
_WIDTHS = {"B": "B", "H": "H", "I": "I" if array("I").itemsize == 4 else "L"}
_BIG_ENDIAN = sys.byteorder == "big"


def le_bytes(values: array[Any]) -> bytes:
    """The array's items as little-endian bytes (the format's byte order on every platform)."""
    if _BIG_ENDIAN:
        values = array(values.typecode, values)
        values.byteswap()
    return values.tobytes()


def from_le(values: array[Any], data: bytes) -> array[Any]:
    values.frombytes(data)
    if _BIG_ENDIAN:
        values.byteswap()
    return values


def shuffle(raw: bytes, width: int) -> bytes:
    """Byte planes: all first bytes, then all second bytes, ... (zstd likes the result)."""
    return b"".join(raw[i::width] for i in range(width))


def unshuffle(data: bytes, width: int) -> bytes:
    n = len(data) // width
    out = bytearray(len(data))
    for i in range(width):
        out[i::width] = data[i * n : (i + 1) * n]
    return bytes(out)


def pack_i64(values: Sequence[int], *, delta: bool) -> bytes | None:
    """Delta-coded (optionally) little-endian int64 byte planes; None if out of range."""
    if delta and values:
        values = [values[0], *map(sub, values[1:], values[:-1])]
    try:
        return shuffle(le_bytes(array("q", values)), 8)
    except OverflowError:
        return None


def unpack_i64(data: bytes, *, delta: bool) -> list[int]:
    values = from_le(array("q"), unshuffle(data, 8))
    return list(accumulate(values)) if delta else values.tolist()


def pack_stream(values: Sequence[int], *, delta: bool) -> bytes:
    """A message-level integer stream: ``Q`` + int64 byte planes, or (MCAP times are uint64,
    beyond int64 in no real log) ``J`` + the values as JSON."""
    packed = pack_i64(values, delta=delta)
    return b"Q" + packed if packed is not None else b"J" + orjson.dumps(list(values))


def unpack_stream(data: bytes, *, delta: bool) -> list[int]:
    if data[:1] == b"J":
        values = orjson.loads(data[1:])
        if not isinstance(values, list) or not all(type(v) is int for v in values):
            raise ColdFormatError("bad integer stream")
        return values
    if data[:1] != b"Q":
        raise ColdFormatError("bad integer stream tag")
    return unpack_i64(data[1:], delta=delta)


def pack_small(values: Sequence[int]) -> tuple[str, bytes]:
    top = max(values, default=0)
    code = "B" if top < 1 << 8 else "H" if top < 1 << 16 else "I"
    return code, le_bytes(array(_WIDTHS[code], values))


def unpack_small(code: str, data: bytes) -> list[int]:
    if code not in _WIDTHS:
        raise ColdFormatError(f"bad integer width {code!r}")
    values = from_le(array(_WIDTHS[code]), data)
    return values.tolist()


def plan(shape: Shape, topic_id: int) -> tuple[list[ColumnKey], list[bool]]:
    """Column keys of a shape's slots on a topic, and which slots are vectors (cached)."""
    found = shape.plans.get(topic_id)
    if found is None:
        keys = [(topic_id, path) for path in shape.paths]
        vectors = [slot in shape.vectors for slot in range(len(keys))]
        found = shape.plans[topic_id] = (keys, vectors)
    return found


def counters(shape: Shape, topic_id: int) -> list[ColumnKey]:
    """The columns whose rows a shape's slots count, in slot order (a vector's rows are
    counted in its lengths column), cached on the shape like its plan."""
    found = shape.plans.get(("counters", topic_id))
    if found is None:
        keys, vectors = plan(shape, topic_id)
        found = [
            (topic_id, (*path, LENGTHS)) if vector else (topic_id, path)
            for (_topic, path), vector in zip(keys, vectors, strict=True)
        ]
        shape.plans[("counters", topic_id)] = found
    return found


def decode_column(codec: str, param: Any, data: bytes, count: int | None = None) -> list[Any]:
    """The values of one column from its codec, the header's parameter and its body bytes
    (``count``: how many, for a constant inside a nullable column, which has no body)."""
    if codec == CONST:
        if count is None:
            raise ColdFormatError("a constant column outside a nullable one")
        return [param] * count
    if codec == INT:
        return unpack_i64(data, delta=True)
    if codec == DEC:
        k, negative_zeros = param
        floats = list(map(truediv, unpack_i64(data, delta=True), repeat(SCALES[int(k)])))
        for at in negative_zeros:
            floats[at] = -0.0
        return floats
    if codec == NULLABLE:
        inner, inner_param, count = param
        mask = data[:count]
        present = iter(decode_column(inner, inner_param, data[count:], mask.count(1)))
        return [next(present) if flag else None for flag in mask]
    if codec == F64:
        values = from_le(array("d"), unshuffle(data, 8))
        return values.tolist()
    if codec == STR:
        code, table = param
        return list(map(table.__getitem__, unpack_small(code, data)))
    if codec == DIGEST:
        code, literals = param
        offsets: list[Any] = unpack_small(code, data)
        if literals:
            pending = iter(literals)
            offsets = [x if x else next(pending) for x in offsets]
        return offsets
    if codec == SENSORS:
        (literals,) = param
        if data.count(0) != len(literals) or data.count(1) + len(literals) != len(data):
            raise ColdFormatError("a sensors column's flags disagree with its literals")
        pending = iter(literals)
        return [DERIVED if flag else next(pending) for flag in data]
    if codec == BOOL:
        return [b != 0 for b in data]
    if codec == JSON:
        values = orjson.loads(data)
        if not isinstance(values, list):
            raise ColdFormatError("a JSON column is not an array")
        return values
    raise ColdFormatError(f"unknown column codec {codec!r}")
