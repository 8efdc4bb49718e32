"""How a proof bundle carries bytes, and reads them back untrusted: base64 of the bytes
(``trace-proof/1`` and ``/2``) or of one raw DEFLATE stream of them (``/3`` and later), every
field of the documented shape or a ``BadBundleError`` (a failed step, never raised out of
``check_bundle``), and all of a bundle's data together inflated within a bound."""

from __future__ import annotations

import base64
import binascii
import zlib
from collections.abc import Mapping
from typing import TypeVar

from trace_runtime.errors import InputError

__all__ = [
    "MAX_INFLATED_BYTES",
    "BadBundleError",
    "DataReader",
    "b64",
    "deflated",
    "field_of",
    "unb64",
]

T = TypeVar("T")

MAX_INFLATED_BYTES = 64 << 20
"""All of a bundle's data together, inflated: a bomb stops here."""


def b64(data: bytes) -> str:
    return base64.b64encode(data).decode()


def deflated(data: bytes) -> str:
    """The base64 of a raw DEFLATE stream (RFC 1951: no zlib header, no checksum) of data."""
    squeeze = zlib.compressobj(9, zlib.DEFLATED, -15)
    return b64(squeeze.compress(data) + squeeze.flush())


class BadBundleError(InputError):
    """A bundle not of the documented shape (reported as a failed step, never raised out)."""


def field_of(bundle: Mapping[str, object], name: str, kind: type[T]) -> T:
    value = bundle.get(name)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise BadBundleError(f"field {name} is missing or not {kind.__name__}")
    return value


def unb64(text: object, what: str) -> bytes:
    if not isinstance(text, str):
        raise BadBundleError(f"{what} is not base64 text")
    try:
        data = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError) as err:
        raise BadBundleError(f"{what} is not base64") from err
    if b64(data) != text:
        raise BadBundleError(f"{what} is not canonical base64")
    return data


def _inflate_exactly(data: bytes, limit: int) -> bytes | None:
    """What ``data`` inflates to when it is one whole raw DEFLATE stream with nothing after
    it, of at most ``limit`` bytes; None otherwise."""
    stream = zlib.decompressobj(-15)
    try:
        out = stream.decompress(data, limit + 1)
    except zlib.error:
        return None
    if not stream.eof or stream.unused_data or stream.unconsumed_tail or len(out) > limit:
        return None
    return out


class DataReader:
    """A bundle's message and reading data: base64 of the bytes (trace-proof/1 and /2), or
    base64 of a raw DEFLATE stream of them (/3). A stream whose final byte has a set bit
    that inflating ignores (its padding) is refused, so no byte of a bundle can change and
    it still verify; another compressor's stream of the same bytes is accepted (the seal's
    digests cover the bytes, not their compression)."""

    def __init__(self, deflated: bool) -> None:
        self.deflated = deflated
        self.left = MAX_INFLATED_BYTES

    def __call__(self, text: object, what: str) -> bytes:
        data = unb64(text, what)
        if not self.deflated:
            return data
        out = _inflate_exactly(data, self.left)
        if out is None:
            raise BadBundleError(f"{what} is not one raw DEFLATE stream within the bounds")
        last = data[-1]
        for bit in range(8):
            if last >> bit & 1:
                cleared = data[:-1] + bytes([last & ~(1 << bit)])
                if _inflate_exactly(cleared, self.left) == out:
                    raise BadBundleError(f"{what}: the stream's padding bits are not zero")
        self.left -= len(out)
        return out
