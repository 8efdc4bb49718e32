"""The cold tier: a lossless columnar codec for blocks of cycles, stored inside MCAP.

A cold segment holds, per block of ``block_cycles`` whole cycles, one MCAP chunk: the
block's signed checkpoints as plain messages, the block itself on ``/trace/cold/block``
(message encoding ``trace-cold-v1``, log time = the earliest log time in the block) and a
small JSON index entry on ``/trace/cold/index`` (log time = the latest), so the chunk index
spans exactly the time the block covers and a seek to t decodes one block. Decoding a block
gives back every message of the input (topic, sequence, log time and the data, byte for
byte), which the input tier's assembler then turns into cycles: seals verify because the
bytes they digest are unchanged.

Inside a block (see docs/storage.md for the byte layout), each JSON message is split into a
*shape* (keys, array lengths) and its leaf values; the values of one leaf path across the
block form a column, and each column gets the cheapest exact coding that fits it: one
constant, delta-coded integers, decimals as delta-coded scaled integers, raw doubles,
dictionary-coded strings, or, for SHA-256 hex strings that are the digest of an earlier
message of the block (seal digests, ``prev``, evidence ref digests), a back-reference to that
message. The whole block is then compressed with zstd. Messages that are not canonical
compact JSON are stored verbatim, so any input round-trips.
"""

from __future__ import annotations

import contextlib
import gc
import hashlib
import struct
import sys
import threading
from array import array
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from itertools import accumulate, chain, repeat
from operator import mul, sub, truediv
from typing import Any

import orjson
import zstandard

from trace_runtime.cycles import Cycle, RawMessage, assemble_hot
from trace_runtime.errors import LogReadError, TraceError
from trace_runtime.records import TOPIC_CHECKPOINT, TOPIC_SEAL
from trace_runtime.tiers._shapes import Shape, ShapeError, compile_shape, describe
from trace_runtime.tiers.warm import assemble_warm

CODEC = "trace-cold-v1"
BLOCK_TOPIC = "/trace/cold/block"
INDEX_TOPIC = "/trace/cold/index"
BLOCK_SCHEMA = ("trace.ColdBlock", "", b"")
INDEX_SCHEMA = (
    "trace.ColdIndex",
    "jsonschema",
    b'{"type":"object","title":"Cold block index entry","properties":{'
    b'"messages":{"type":"integer"},"cycles":{"type":"integer"},'
    b'"first_cycle":{"type":["integer","null"]},"last_cycle":{"type":["integer","null"]},'
    b'"first_seal":{"type":["string","null"]},"last_seal":{"type":["string","null"]}}}',
)
PLAIN_TOPICS = frozenset({TOPIC_CHECKPOINT})
"""Topics kept out of blocks, as ordinary MCAP messages in the block's chunk: signed chain
heads stay readable by any MCAP tool without decoding. The block records where they were."""
DEFAULT_BLOCK_CYCLES = 256
DEFAULT_LEVEL = 11
_MAGIC = b"TCB\x01"
_MAX_BLOCK_BYTES = 1 << 31
_MAX_NEW_SHAPES_PER_TOPIC = 64
_SHAPE_CACHE_LIMIT = 4096
_NEG_ZERO = struct.pack("<d", -0.0)
_SCALES = tuple(10.0**k for k in range(23))
_DEC_TRIES = 10
_MISMATCH = (KeyError, IndexError, TypeError, AttributeError)
SEAL_ANCHOR_CYCLES = 64
"""Every this-many-th seal of a block keeps its ``prev`` digest as a literal instead of a
back-reference (~0.5 byte a cycle at 64): a seek then rebuilds the hash chain from the
nearest such anchor, not from the start of the block (``PartialBlock``); readers need not
know it. Measured on a 2 h sim log: a seek 2.7-2.9x faster than a whole-block decode with
anchors every 32 or 64 cycles (the fixed cost of opening a block dominates), 1.4x
without; 64 costs half the bytes of 32 (+0.5 vs +1.15 B a cycle)."""
_SEAL_PREV = (TOPIC_SEAL, ("prev",))

# column codecs
_CONST, _INT, _DEC, _F64, _BOOL, _STR, _DIGEST, _JSON = "c", "i", "d", "f", "b", "s", "h", "j"
_NULLABLE = "n"

Assembler = Callable[[Sequence[RawMessage], str], list[Cycle]]


class ColdFormatError(TraceError, ValueError):
    """A cold block is malformed (wrapped into ``LogReadError`` by callers). A ``TraceError``
    so that one that escapes still maps to an exit code; a ``ValueError`` for older callers."""


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic GC while a block is taken apart or put together.

    A block makes and keeps hundreds of thousands of small acyclic objects (parsed messages,
    rows, columns); the collector would walk them again and again for nothing, a large
    share of the time. Reference counting still frees everything as usual.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


# --- compiled shapes, shared by encoders and decoders ------------------------------------

_COMPILED: dict[bytes, Shape] = {}


def _shape_for(descriptor: Any, key: bytes) -> Shape:
    shape = _COMPILED.get(key)
    if shape is None:
        if len(_COMPILED) >= _SHAPE_CACHE_LIMIT:
            _COMPILED.clear()
        shape = compile_shape(descriptor, key)
        _COMPILED[key] = shape
    return shape


# --- integers and byte planes ------------------------------------------------------------


# Width codes in the format -> array typecodes of exactly 1, 2 and 4 bytes on this platform.
_WIDTHS = {"B": "B", "H": "H", "I": "I" if array("I").itemsize == 4 else "L"}
_BIG_ENDIAN = sys.byteorder == "big"


def _le_bytes(values: array[Any]) -> bytes:
    """The array's items as little-endian bytes (the format's byte order on every platform)."""
    if _BIG_ENDIAN:
        values = array(values.typecode, values)
        values.byteswap()
    return values.tobytes()


def _from_le(values: array[Any], data: bytes) -> array[Any]:
    values.frombytes(data)
    if _BIG_ENDIAN:
        values.byteswap()
    return values


def _shuffle(raw: bytes, width: int) -> bytes:
    """Byte planes: all first bytes, then all second bytes, ... (zstd likes the result)."""
    return b"".join(raw[i::width] for i in range(width))


def _unshuffle(data: bytes, width: int) -> bytes:
    n = len(data) // width
    out = bytearray(len(data))
    for i in range(width):
        out[i::width] = data[i * n : (i + 1) * n]
    return bytes(out)


def _pack_i64(values: Sequence[int], *, delta: bool) -> bytes | None:
    """Delta-coded (optionally) little-endian int64 byte planes; None if out of range."""
    if delta and values:
        values = [values[0], *map(sub, values[1:], values[:-1])]
    try:
        return _shuffle(_le_bytes(array("q", values)), 8)
    except OverflowError:
        return None


def _unpack_i64(data: bytes, *, delta: bool) -> list[int]:
    values = _from_le(array("q"), _unshuffle(data, 8))
    return list(accumulate(values)) if delta else values.tolist()


def _pack_stream(values: Sequence[int], *, delta: bool) -> bytes:
    """A message-level integer stream: ``Q`` + int64 byte planes, or (MCAP times are uint64,
    beyond int64 in no real log) ``J`` + the values as JSON."""
    packed = _pack_i64(values, delta=delta)
    return b"Q" + packed if packed is not None else b"J" + orjson.dumps(list(values))


def _unpack_stream(data: bytes, *, delta: bool) -> list[int]:
    if data[:1] == b"J":
        values = orjson.loads(data[1:])
        if not isinstance(values, list) or not all(type(v) is int for v in values):
            raise ColdFormatError("bad integer stream")
        return values
    if data[:1] != b"Q":
        raise ColdFormatError("bad integer stream tag")
    return _unpack_i64(data[1:], delta=delta)


def _pack_small(values: Sequence[int]) -> tuple[str, bytes]:
    top = max(values, default=0)
    code = "B" if top < 1 << 8 else "H" if top < 1 << 16 else "I"
    return code, _le_bytes(array(_WIDTHS[code], values))


def _unpack_small(code: str, data: bytes) -> list[int]:
    if code not in _WIDTHS:
        raise ColdFormatError(f"bad integer width {code!r}")
    values = _from_le(array(_WIDTHS[code]), data)
    return values.tolist()


# --- column coding -------------------------------------------------------------------------


@dataclass(slots=True)
class _Column:
    """The values of one (topic, leaf path) across a block and where they came from.

    ``groups`` lists the shape groups whose rows the values are, in order; it is None for
    the element columns of vectors, whose values are not one per row.
    """

    values: list[Any] = field(default_factory=list)
    groups: list[int] | None = field(default_factory=list)


LENGTHS = -1
"""Last path element of a vector's lengths column (element columns end in the index)."""


FLAT = -2
"""Last path element of a vector's flat column: every element of every row, in row order."""


def _add_vectors(
    columns: dict[tuple[int, tuple[Any, ...]], _Column],
    key: tuple[int, tuple[Any, ...]],
    vectors: list[list[Any]],
) -> None:
    """A vector leaf's values across the block: a column of lengths, then either one column
    per element index (every vector as long as the others, e.g. positions) or one flat
    column of all elements (lengths vary, e.g. the ranges of clusters of beams)."""
    topic_id, path = key
    lengths = list(map(len, vectors))
    _extend(columns, (topic_id, (*path, LENGTHS)), lengths)
    if not lengths:
        return
    if lengths.count(lengths[0]) == len(lengths):
        for index, values in enumerate(zip(*vectors, strict=True)):
            _extend(columns, (topic_id, (*path, index)), values)
    else:
        _extend(columns, (topic_id, (*path, FLAT)), chain.from_iterable(vectors))


def _extend(
    columns: dict[tuple[int, tuple[Any, ...]], _Column],
    key: tuple[int, tuple[Any, ...]],
    values: Iterable[Any],
) -> None:
    column = columns.get(key)
    if column is None:
        column = columns[key] = _Column(groups=None)
    column.groups = None  # shared with a vector's elements: no longer one value per row
    column.values += values


class BlockEncoder:
    """Encodes blocks of messages; keeps shapes and per-column hints from block to block."""

    def __init__(self, level: int = DEFAULT_LEVEL) -> None:
        self._zstd = zstandard.ZstdCompressor(level=level)
        self._by_sig: dict[tuple[str, int, int], list[Shape]] = {}
        self._hints: dict[tuple[str, tuple[Any, ...]], int] = {}
        self._noncanonical: set[str] = set()
        self._strict = False
        self._last_raw = 0
        self._last_digests: list[str] = []
        self.raw_messages = 0
        self.messages = 0
        self.retries = 0
        """Blocks whose fast encoding did not decode exactly and were encoded again, strictly."""

    def encode(self, messages: Sequence[RawMessage], tier: str, plain: Sequence[int] = ()) -> bytes:
        """One block: ``messages`` in file order, ``tier`` = how their cycles assemble.

        ``plain``: positions (in the whole stream) of the messages stored beside the block.
        """
        return self.encode_checked(messages, tier, plain)[0]

    def encode_checked(
        self, messages: Sequence[RawMessage], tier: str, plain: Sequence[int] = ()
    ) -> tuple[bytes, DecodedBlock]:
        """``encode``, and the block as it decodes (which equals ``messages``).

        Every block is decoded again before it is returned and must give back ``messages``
        exactly. The fast encoding trusts a topic's messages to be canonical JSON (compact,
        as orjson writes it) unless one of them was not before; when the block does not
        decode exactly it is encoded again with every message checked, and failing that,
        with every message verbatim.
        """
        expected = list(messages)
        with gc_paused():
            for strict, verbatim in ((False, False), (True, False), (True, True)):
                self._strict = strict
                data = self._encode(expected, tier, plain, verbatim=verbatim)
                decoded = _check_decode(data, self._last_digests)
                # (a list == of the messages: a C loop over the dataclass's __eq__, faster
                # than comparing two lists of field tuples)
                if decoded.plain == list(plain) and decoded.messages == expected:
                    break
                self.retries += 1
            else:
                raise ColdFormatError("a block does not decode to its messages (codec bug)")
        self.messages += len(expected)
        self.raw_messages += self._last_raw
        return data, decoded

    def _encode(
        self, messages: Sequence[RawMessage], tier: str, plain: Sequence[int], *, verbatim: bool
    ) -> bytes:
        topics: dict[str, int] = {}
        topic_ids: list[int] = []
        shape_ids: list[int] = []
        seq_deltas: list[int] = []
        raw: list[bytes] = []
        groups: dict[tuple[int, Shape], int] = {}
        group_rows: list[list[tuple[Any, ...]]] = []
        group_msgs: list[list[int]] = []
        group_keys: list[tuple[int, Shape]] = []
        new_shapes: Counter[str] = Counter()
        last_seq: dict[int, int] = {}
        digests: dict[str, int] = {}
        digest_list: list[str] = []
        sha256 = hashlib.sha256
        loads, dumps = orjson.loads, orjson.dumps
        by_sig = self._by_sig
        strict, noncanonical = self._strict, self._noncanonical

        for index, msg in enumerate(messages):
            topic_id = topics.setdefault(msg.topic, len(topics))
            topic_ids.append(topic_id)
            seq_deltas.append(msg.sequence - last_seq.get(topic_id, 0))
            last_seq[topic_id] = msg.sequence
            data = msg.data
            digest = sha256(data).hexdigest()
            digest_list.append(digest)
            digests.setdefault(digest, index)
            shape: Shape | None = None
            row: tuple[Any, ...] = ()
            try:
                value = None if verbatim else loads(data)
            except orjson.JSONDecodeError:
                value = None
            if type(value) is dict or type(value) is list:
                # Candidate shapes are found by the message's count of objects and arrays:
                # one dict lookup, and a shape that would take a container for a scalar
                # (valid, but coded poorly) is never even tried.
                sig = (msg.topic, data.count(b"{"), data.count(b"["))
                for candidate in by_sig.get(sig, ()):
                    try:
                        row = candidate.extract(value)
                    except _MISMATCH:
                        continue
                    shape = candidate
                    break
                if shape is None and new_shapes[msg.topic] < _MAX_NEW_SHAPES_PER_TOPIC:
                    shape = self._new_shape(value)
                    if shape is not None:
                        new_shapes[msg.topic] += 1
                        row = shape.extract(value)
                        if len(by_sig) >= _SHAPE_CACHE_LIMIT:
                            by_sig.clear()
                        by_sig.setdefault(sig, []).insert(0, shape)
                if shape is not None and (strict or msg.topic in noncanonical):
                    try:
                        canonical = dumps(value) == data
                    except orjson.JSONEncodeError:
                        canonical = False
                    if not canonical:
                        noncanonical.add(msg.topic)
                        shape = None
            if shape is None:
                raw.append(data)
                shape_ids.append(0)
                continue
            key = (topic_id, shape)
            group = groups.get(key)
            if group is None:
                group = groups[key] = len(group_rows)
                group_rows.append([])
                group_msgs.append([])
                group_keys.append(key)
            group_rows[group].append(row)
            group_msgs[group].append(index)
            shape_ids.append(group + 1)

        self._last_raw = len(raw)
        self._last_digests = digest_list
        topic_names = list(topics)
        columns: dict[tuple[int, tuple[Any, ...]], _Column] = {}
        vector_values: dict[tuple[int, tuple[Any, ...]], list[list[Any]]] = {}
        for group, (topic_id, shape) in enumerate(group_keys):
            vectors = shape.vectors
            slots = zip(*group_rows[group], strict=True)
            for slot, (path, values) in enumerate(zip(shape.paths, slots, strict=True)):
                if slot in vectors:
                    vector_values.setdefault((topic_id, path), []).extend(values)
                    continue
                column = columns.get((topic_id, path))
                if column is None:
                    column = columns[(topic_id, path)] = _Column()
                column.values += values
                if column.groups is not None:
                    column.groups.append(group)

        for vector_key, vectors_at in vector_values.items():
            _add_vectors(columns, vector_key, vectors_at)

        payload: list[bytes] = []
        col_headers: list[list[Any]] = []
        for (topic_id, path), column in columns.items():
            hint_key = (topic_names[topic_id], path)
            codec, param, body = self._encode_column(column, hint_key, digests, group_msgs)
            payload.append(body)
            col_headers.append([topic_id, list(path), codec, len(body), param])

        time_body = _pack_stream([m.log_time_ns for m in messages], delta=True)
        seq_body = _pack_stream(seq_deltas, delta=False)
        topic_code, topic_body = _pack_small(topic_ids)
        shape_code, shape_body = _pack_small(shape_ids)
        raw_len_body = _pack_i64([len(r) for r in raw], delta=False) or b""
        fixed = [topic_body, shape_body, seq_body, time_body, raw_len_body, b"".join(raw)]
        header = {
            "tier": tier,
            "n": len(messages),
            "topics": topic_names,
            # descriptors as JSON text: a decoder looks its compiled shape up by these bytes
            "shapes": [[t, s.key.decode()] for t, s in group_keys],
            "msg": [topic_code, shape_code, *(len(b) for b in fixed)],
            "cols": col_headers,
            "plain": list(plain),
        }
        head = orjson.dumps(header)
        body = b"".join([struct.pack("<I", len(head)), head, *fixed, *payload])
        return _MAGIC + self._zstd.compress(body)

    def _new_shape(self, value: Any) -> Shape | None:
        try:
            descriptor = describe(value)
        except ShapeError:
            return None
        return _shape_for(descriptor, orjson.dumps(descriptor))

    def _encode_column(
        self,
        column: _Column,
        hint_key: tuple[str, tuple[Any, ...]],
        digests: dict[str, int],
        group_msgs: list[list[int]],
    ) -> tuple[str, Any, bytes]:
        values = column.values
        types = set(map(type, values))
        if types <= {str, type(None)} and str in types:
            if values.count(values[0]) == len(values):
                return _CONST, values[0], b""
            anchored = SEAL_ANCHOR_CYCLES if hint_key == _SEAL_PREV else 0
            return _encode_strings(
                values, digests, lambda: _message_indexes(column, group_msgs), anchored
            )
        if len(types) == 2 and type(None) in types:
            kind = (types - {type(None)}).pop()
            if kind is float or kind is int or kind is bool:
                # Nullable numbers: a presence mask, and the numbers coded as a column.
                mask = bytes([v is not None for v in values])
                present = [v for v in values if v is not None]
                codec, param, body = self._encode_typed(kind, present, hint_key)
                return _NULLABLE, [codec, param, len(mask)], mask + body
        if len(types) == 1:
            return self._encode_typed(types.pop(), values, hint_key)
        return _JSON, None, orjson.dumps(values)

    def _encode_typed(
        self, kind: type, values: list[Any], hint_key: tuple[str, tuple[Any, ...]]
    ) -> tuple[str, Any, bytes]:
        """A column whose values all have type ``kind`` (and are not strings)."""
        n = len(values)
        if kind is float:
            raw = _le_bytes(array("d", values))
            if raw == raw[:8] * n:
                return _CONST, values[0], b""
            return self._encode_floats(values, raw, hint_key)
        if values.count(values[0]) == n:
            return _CONST, values[0], b""
        if kind is int:
            packed = _pack_i64(values, delta=True)
            if packed is not None:
                return _INT, None, packed
        elif kind is bool:
            return _BOOL, None, bytes(values)
        return _JSON, None, orjson.dumps(values)

    def _encode_floats(
        self, values: list[float], raw: bytes, hint_key: tuple[str, tuple[Any, ...]]
    ) -> tuple[str, Any, bytes]:
        hint = self._hints.get(hint_key)
        if hint != -1:
            # -0.0 == 0.0, so the check below cannot see a lost sign: list where they were.
            negative_zeros = _negative_zeros(values, raw)
            tries = range(_DEC_TRIES) if hint is None else (hint, *range(_DEC_TRIES))
            for k in tries:
                scale = _SCALES[k]
                try:
                    ints = list(map(round, map(mul, values, repeat(scale))))
                except OverflowError:  # beyond the float range once scaled: not a decimal
                    break
                if list(map(truediv, ints, repeat(scale))) == values:
                    packed = _pack_i64(ints, delta=True)
                    if packed is not None:
                        self._hints[hint_key] = k
                        return _DEC, [k, negative_zeros], packed
        self._hints[hint_key] = -1
        return _F64, None, _shuffle(raw, 8)


def _negative_zeros(values: list[float], raw: bytes) -> list[int]:
    """Positions of -0.0 in ``values`` (``raw`` is their float64 bytes)."""
    if 0.0 not in values:
        return []
    found = []
    at = raw.find(_NEG_ZERO)
    while at != -1:
        if at % 8 == 0:
            found.append(at // 8)
        at = raw.find(_NEG_ZERO, at + 1)
    return found


def _message_indexes(column: _Column, group_msgs: list[list[int]]) -> list[int] | None:
    if column.groups is None:
        return None
    out: list[int] = []
    for group in column.groups:
        out += group_msgs[group]
    return out


def _encode_strings(
    values: list[str],
    digests: dict[str, int],
    indexes: Callable[[], list[int] | None],
    anchor_every: int = 0,
) -> tuple[str, Any, bytes]:
    """A string column: digest back-references, else a dictionary. ``anchor_every`` > 0
    keeps every that-many-th value (in message order) a literal: seal anchors."""
    refs = list(map(digests.get, values))
    at_rows = indexes() if refs.count(None) * 2 < len(refs) else None
    if at_rows is not None:
        if anchor_every:
            ranks = {at: rank for rank, at in enumerate(sorted(at_rows))}
            anchors = {at for at, rank in ranks.items() if rank % anchor_every == 0}
            refs = [None if at in anchors else ref for ref, at in zip(refs, at_rows, strict=True)]
        # Mostly digests of earlier messages: store how far back each one is.
        offsets: list[int] = []
        literals: list[str] = []
        for value, ref, at in zip(values, refs, at_rows, strict=True):
            if ref is not None and ref < at:
                offsets.append(at - ref)
            else:
                offsets.append(0)
                literals.append(value)
        code, body = _pack_small(offsets)
        return _DIGEST, [code, literals], body
    table = list(dict.fromkeys(values))
    position = {s: i for i, s in enumerate(table)}
    code, body = _pack_small(list(map(position.__getitem__, values)))
    return _STR, [code, table], body


# --- decoding --------------------------------------------------------------------------------

_DECOMPRESSOR = zstandard.ZstdDecompressor()


@dataclass(frozen=True, slots=True)
class DecodedBlock:
    """A block's messages as they were, the tier they assemble as, and where the messages
    stored beside the block (``PLAIN_TOPICS``) go back in."""

    tier: str
    messages: list[RawMessage]
    plain: list[int]


@contextlib.contextmanager
def _malformed_as_format_error() -> Iterator[None]:
    """Whatever a damaged block makes the decoder trip over becomes one ``ColdFormatError``."""
    try:
        yield
    except ColdFormatError:
        raise
    except (zstandard.ZstdError, orjson.JSONDecodeError, struct.error) as err:
        raise ColdFormatError(f"corrupt cold block ({err})") from err
    except (KeyError, IndexError, TypeError, ValueError, ShapeError) as err:
        raise ColdFormatError(f"malformed cold block ({type(err).__name__}: {err})") from err


def _block_body(block: bytes) -> bytes:
    """The decompressed body of a block (every decode, whole or partial, starts here)."""
    if block[:4] != _MAGIC:
        raise ColdFormatError("not a trace-cold-v1 block (bad magic)")
    with _malformed_as_format_error():
        return _DECOMPRESSOR.decompress(block[4:], max_output_size=_MAX_BLOCK_BYTES)


def decode_block(block: bytes) -> DecodedBlock:
    """Decode one block: every message byte for byte, in order (plain ones left out)."""
    body = _block_body(block)
    with _malformed_as_format_error(), gc_paused():
        return _decode_body(body)


def _check_decode(block: bytes, digests: list[str]) -> DecodedBlock:
    """``decode_block`` for the encoder's check, given the digests of the messages the block
    was made from: a digest reference is resolved from them instead of hashing the message
    it points at again. The check then compares every decoded message with its input, so
    when it passes each digest used was the digest of the decoded bytes too, and a plain
    decode gives the same result (when it fails, the block is not used)."""
    body = _block_body(block)
    with _malformed_as_format_error(), gc_paused():
        return _decode_body(body, dict(enumerate(digests)))


@dataclass(slots=True)
class _BlockStreams:
    """What every decode of a block reads first: its header, the per-message streams
    (topic, shape, sequence, time; the raw messages no shape describes) and its compiled
    shapes. ``columns_at`` is where the column bodies start."""

    header: dict[str, Any]
    n: int
    topic_names: list[str]
    topic_ids: list[int]
    shape_ids: list[int]
    sequences: list[int]
    times: list[int]
    raw_lens: list[int]
    raw_body: bytes
    shapes: list[tuple[int, Shape]]
    columns_at: int

    @classmethod
    def read(cls, body: bytes) -> _BlockStreams:
        (head_len,) = struct.unpack_from("<I", body, 0)
        header = orjson.loads(body[4 : 4 + head_len])
        pos = 4 + head_len
        n = int(header["n"])
        topic_code, shape_code, *sizes = header["msg"]
        parts: list[bytes] = []
        for size in sizes:
            parts.append(body[pos : pos + size])
            pos += size
        topic_body, shape_body, seq_body, time_body, raw_len_body, raw_body = parts
        topic_ids = _unpack_small(topic_code, topic_body)
        shape_ids = _unpack_small(shape_code, shape_body)
        seq_deltas = _unpack_stream(seq_body, delta=False)
        times = _unpack_stream(time_body, delta=True)
        raw_lens = _unpack_i64(raw_len_body, delta=False) if raw_len_body else []
        if not (len(topic_ids) == len(shape_ids) == len(seq_deltas) == len(times) == n):
            raise ColdFormatError("message streams disagree on the message count")
        sequences: list[int] = []
        last_seq: dict[int, int] = {}
        for topic_id, delta in zip(topic_ids, seq_deltas, strict=True):
            last_seq[topic_id] = sequence = last_seq.get(topic_id, 0) + delta
            sequences.append(sequence)
        shapes: list[tuple[int, Shape]] = []
        for topic_id, text in header["shapes"]:
            key = text.encode()
            shape = _COMPILED.get(key)
            if shape is None:
                shape = _shape_for(orjson.loads(key), key)  # checks the descriptor
            shapes.append((int(topic_id), shape))
        topic_names = [str(t) for t in header["topics"]]
        return cls(
            header,
            n,
            topic_names,
            topic_ids,
            shape_ids,
            sequences,
            times,
            raw_lens,
            raw_body,
            shapes,
            pos,
        )


def _decode_body(body: bytes, known_digests: dict[int, str] | None = None) -> DecodedBlock:
    """A block body's messages; ``known_digests`` (message position -> SHA-256 hex) is
    only ever the encoder's check (``_check_decode``)."""
    streams = _BlockStreams.read(body)
    header, n, shapes = streams.header, streams.n, streams.shapes
    shape_ids, raw_lens, raw_body = streams.shape_ids, streams.raw_lens, streams.raw_body
    pos = streams.columns_at

    reader = _ColumnReader()
    for topic_id, path, codec, size, param in header["cols"]:
        key = (int(topic_id), tuple(path))
        if codec == _CONST:
            reader.constants[key] = param  # no body: one value, repeated for every row
        else:
            reader.columns[key] = _decode_column(codec, param, body[pos : pos + size])
        if codec == _DIGEST:
            reader.digests.add(key)
        pos += size

    positions: list[list[int]] = [[] for _ in range(len(shapes) + 1)]
    for index, group in enumerate(shape_ids):
        positions[group].append(index)
    if len(positions) != len(shapes) + 1:
        raise ColdFormatError("a message names a shape the block does not have")
    datas: list[bytes] = [b""] * n
    raw_at = 0
    for index, size in zip(positions[0], raw_lens, strict=True):
        datas[index] = raw_body[raw_at : raw_at + size]
        raw_at += size

    # A shape whose leaves hold digests of earlier messages (seals, evidence refs) can be
    # built only once those messages are. Everything else is built first, in bulk; then
    # each waiting group whose targets are all built (refs to sensor readings), in bulk;
    # what is left (seals, which name the previous seal) in message order.
    dumps = orjson.dumps
    built = bytearray(n)
    for index in positions[0]:
        built[index] = 1
    waiting: list[tuple[int, Shape, list[Sequence[Any]], list[int]]] = []
    for group, (topic_id, shape) in enumerate(shapes, start=1):
        count = len(positions[group])
        keys, vectors = _plan(shape, topic_id)
        slices = reader.take_all(keys, vectors, count)
        rows: Iterable[Sequence[Any]] = zip(*slices, strict=True) if slices else repeat((), count)
        slots = [i for i, key in enumerate(keys) if key in reader.digests] if reader.digests else []
        if slots:
            waiting.append((group, shape, list(rows), slots))
            continue
        for index, data in zip(positions[group], map(dumps, map(shape.build, rows)), strict=True):
            datas[index] = data
            built[index] = 1
    hexes: dict[int, str] = known_digests if known_digests is not None else {}
    sequential = []
    for group, shape, rows_list, slots in waiting:
        filled = _fill_digests(
            positions[group], rows_list, slots, datas=datas, built=built, hexes=hexes
        )
        if filled is None:
            sequential.append((group, shape, iter(rows_list), slots))
            continue
        for index, data in zip(positions[group], map(dumps, map(shape.build, filled)), strict=True):
            datas[index] = data
            built[index] = 1
    if sequential:
        order = sorted((i, entry) for entry in sequential for i in positions[entry[0]])
        for index, (_group, shape, rows_left, digest_slots) in order:
            row = list(next(rows_left))
            for slot in digest_slots:
                back = row[slot]
                if type(back) is int:
                    row[slot] = _hex_of(datas, hexes, index - back)
            datas[index] = dumps(shape.build(row))

    topics = list(map(streams.topic_names.__getitem__, streams.topic_ids))
    messages = list(map(RawMessage, topics, streams.sequences, streams.times, datas))
    plain = [int(p) for p in header.get("plain", [])]
    return DecodedBlock(str(header["tier"]), messages, plain)


class _ColumnReader:
    """Hands out the next values of each decoded column, shape group by shape group."""

    def __init__(self) -> None:
        self.columns: dict[tuple[int, tuple[Any, ...]], list[Any]] = {}
        self.constants: dict[tuple[int, tuple[Any, ...]], Any] = {}
        self.digests: set[tuple[int, tuple[Any, ...]]] = set()
        self._taken: dict[tuple[int, tuple[Any, ...]], int] = {}

    def take(self, key: tuple[int, tuple[Any, ...]], count: int) -> list[Any]:
        if key in self.constants:
            return [self.constants[key]] * count
        values = self.columns[key]
        start = self._taken.get(key, 0)
        if start + count > len(values):
            raise ColdFormatError("a column is shorter than its shapes need")
        self._taken[key] = start + count
        return values[start : start + count]

    def take_all(
        self, keys: list[tuple[int, tuple[Any, ...]]], vectors: list[bool], count: int
    ) -> list[list[Any]]:
        """``take`` (or ``take_vectors``) of every key of a shape group, in one call: a
        block has hundreds of groups times dozens of keys, and this is the decoder's loop."""
        columns, constants, taken = self.columns, self.constants, self._taken
        out: list[list[Any]] = []
        for key, vector in zip(keys, vectors, strict=True):
            if vector:
                out.append(self.take_vectors(key, count))
            elif key in constants:
                out.append([constants[key]] * count)
            else:
                values = columns[key]
                start = taken.get(key, 0)
                end = start + count
                if end > len(values):
                    raise ColdFormatError("a column is shorter than its shapes need")
                taken[key] = end
                out.append(values[start:end])
        return out

    def take_vectors(self, key: tuple[int, tuple[Any, ...]], count: int) -> list[Any]:
        topic_id, path = key
        lengths = self.take((topic_id, (*path, LENGTHS)), count)
        if not lengths:
            return []
        flat_key = (topic_id, (*path, FLAT))
        if flat_key in self.columns or flat_key in self.constants:
            flat = self.take(flat_key, sum(lengths))
            ends = list(accumulate(lengths))
            return [flat[end - n : end] for n, end in zip(lengths, ends, strict=True)]
        width = lengths[0]
        if lengths.count(width) != len(lengths):
            raise ColdFormatError("vectors of different lengths without a flat column")
        if width == 0:
            return [[] for _ in lengths]
        elements = [self.take((topic_id, (*path, i)), count) for i in range(width)]
        return list(map(list, zip(*elements, strict=True)))


def _plan(shape: Shape, topic_id: int) -> tuple[list[tuple[int, tuple[Any, ...]]], list[bool]]:
    """Column keys of a shape's slots on a topic, and which slots are vectors (cached)."""
    plan = shape.plans.get(topic_id)
    if plan is None:
        keys = [(topic_id, path) for path in shape.paths]
        vectors = [slot in shape.vectors for slot in range(len(keys))]
        plan = shape.plans[topic_id] = (keys, vectors)
    return plan


def _counters(shape: Shape, topic_id: int) -> list[tuple[int, tuple[Any, ...]]]:
    """The columns whose rows a shape's slots count, in slot order (a vector's rows are
    counted in its lengths column), cached on the shape like its plan."""
    found = shape.plans.get(("counters", topic_id))
    if found is None:
        keys, vectors = _plan(shape, topic_id)
        found = [
            (topic_id, (*path, LENGTHS)) if vector else (topic_id, path)
            for (_topic, path), vector in zip(keys, vectors, strict=True)
        ]
        shape.plans[("counters", topic_id)] = found
    return found


def _fill_digests(
    positions: list[int],
    rows: list[Sequence[Any]],
    slots: list[int],
    *,
    datas: list[bytes],
    built: bytearray,
    hexes: dict[int, str],
) -> list[Sequence[Any]] | None:
    """Rows with their digest references resolved, or None if one points at an unbuilt message."""
    out: list[Sequence[Any]] = []
    for index, row in zip(positions, rows, strict=True):
        fixed = list(row)
        for slot in slots:
            back = fixed[slot]
            if type(back) is int:
                at = index - back
                if at < 0 or not built[at]:
                    return None
                fixed[slot] = _hex_of(datas, hexes, at)
        out.append(fixed)
    return out


def _hex_of(datas: list[bytes], cache: dict[int, str], at: int) -> str:
    if at < 0:
        raise ColdFormatError("a digest reference points before the block")
    value = cache.get(at)
    if value is None:
        value = cache[at] = hashlib.sha256(datas[at]).hexdigest()
    return value


def _decode_column(codec: str, param: Any, data: bytes, count: int | None = None) -> list[Any]:
    if codec == _CONST:
        if count is None:
            raise ColdFormatError("a constant column outside a nullable one")
        return [param] * count
    if codec == _INT:
        return _unpack_i64(data, delta=True)
    if codec == _DEC:
        k, negative_zeros = param
        floats = list(map(truediv, _unpack_i64(data, delta=True), repeat(_SCALES[int(k)])))
        for at in negative_zeros:
            floats[at] = -0.0
        return floats
    if codec == _NULLABLE:
        inner, inner_param, count = param
        mask = data[:count]
        present = iter(_decode_column(inner, inner_param, data[count:], mask.count(1)))
        return [next(present) if flag else None for flag in mask]
    if codec == _F64:
        values = _from_le(array("d"), _unshuffle(data, 8))
        return values.tolist()
    if codec == _STR:
        code, table = param
        return list(map(table.__getitem__, _unpack_small(code, data)))
    if codec == _DIGEST:
        code, literals = param
        offsets: list[Any] = _unpack_small(code, data)
        if literals:
            pending = iter(literals)
            offsets = [x if x else next(pending) for x in offsets]
        return offsets
    if codec == _BOOL:
        return [b != 0 for b in data]
    if codec == _JSON:
        values = orjson.loads(data)
        if not isinstance(values, list):
            raise ColdFormatError("a JSON column is not an array")
        return values
    raise ColdFormatError(f"unknown column codec {codec!r}")


# --- partial decoding: one cycle of a block ------------------------------------------------


class PartialBlock:
    """A block opened for building only some of its messages (a seek wants one cycle).

    The message streams and the column table are read at once; a column is decoded the
    first time a message that needs it is built, and a shape group's rows are cut from
    its columns the first time one of them is needed. A message's digest references are
    followed back first, so building a cycle builds just the messages its bytes depend
    on: its own, the sensor readings its evidence names, and the seals (with their
    cycles) back to the nearest seal whose ``prev`` the block stores as a literal (the
    encoder writes one every ``SEAL_ANCHOR_CYCLES`` cycles; a block without such anchors
    is built back to its start, correctly, only more slowly).
    """

    def __init__(self, body: bytes) -> None:
        streams = _BlockStreams.read(body)
        header, pos, raw_lens, raw_body = (
            streams.header,
            streams.columns_at,
            streams.raw_lens,
            streams.raw_body,
        )
        self.n = n = streams.n
        self.tier = str(header["tier"])
        self.plain = [int(p) for p in header.get("plain", [])]
        self.topic_names = streams.topic_names
        self.topic_ids = streams.topic_ids
        self.shape_ids = streams.shape_ids
        self.times = streams.times
        self.sequences = streams.sequences
        self.shapes = streams.shapes

        self._body = body
        self._specs: dict[tuple[int, tuple[Any, ...]], tuple[str, Any, int, int]] = {}
        self._constants: dict[tuple[int, tuple[Any, ...]], Any] = {}
        self._digest_keys: set[tuple[int, tuple[Any, ...]]] = set()
        for topic_id, path, codec, size, param in header["cols"]:
            key = (int(topic_id), tuple(path))
            if codec == _CONST:
                self._constants[key] = param
            else:
                self._specs[key] = (codec, param, pos, size)
            if codec == _DIGEST:
                self._digest_keys.add(key)
            pos += size
        self._values: dict[tuple[int, tuple[Any, ...]], list[Any]] = {}

        # each message's row within its shape group
        counts = [0] * (len(self.shapes) + 1)
        self.row_of: list[int] = []
        for group in self.shape_ids:
            if group > len(self.shapes):
                raise ColdFormatError("a message names a shape the block does not have")
            self.row_of.append(counts[group])
            counts[group] += 1
        self.datas: list[bytes | None] = [None] * n
        raw_at = 0
        raw_positions = [i for i, group in enumerate(self.shape_ids) if group == 0]
        for index, size in zip(raw_positions, raw_lens, strict=True):
            self.datas[index] = raw_body[raw_at : raw_at + size]
            raw_at += size
        self._counts = counts
        self._layout = self._lay_out(counts)
        self._by_path: dict[tuple[int, tuple[Any, ...]], list[tuple[int, int]]] | None = None
        self._flat_starts: dict[tuple[int, tuple[Any, ...]], list[int]] = {}
        self._rows: dict[int, list[Sequence[Any]]] = {}
        self._digest_slots: dict[int, list[int]] = {}

    def _slots_of_digests(self, group: int) -> list[int]:
        """The slots of a group whose column holds digest back-references."""
        slots = self._digest_slots.get(group)
        if slots is None:
            topic_id, shape = self.shapes[group - 1]
            keys = _plan(shape, topic_id)[0]
            slots = [i for i, key in enumerate(keys) if key in self._digest_keys]
            self._digest_slots[group] = slots
        return slots

    def _column(self, key: tuple[int, tuple[Any, ...]]) -> list[Any]:
        values = self._values.get(key)
        if values is None:
            codec, param, pos, size = self._specs[key]
            data = self._body[pos : pos + size]
            values = self._values[key] = _decode_column(codec, param, data)
        return values

    def _cut(self, key: tuple[int, tuple[Any, ...]], start: int, count: int) -> list[Any]:
        if key in self._constants:
            return [self._constants[key]] * count
        values = self._column(key)
        if start + count > len(values):
            raise ColdFormatError("a column is shorter than its shapes need")
        return values[start : start + count]

    def _lay_out(self, counts: list[int]) -> list[list[int]]:
        """Where each shape group's slots start in their columns: groups take their rows
        from the columns in group order, as the encoder put them there. A vector slot
        counts its rows in its lengths column (a scalar leaf of the same path, where the
        array was null, has a column of its own)."""
        taken: dict[tuple[int, tuple[Any, ...]], int] = {}
        get = taken.get
        layout: list[list[int]] = []
        for group, (topic_id, shape) in enumerate(self.shapes, start=1):
            count = counts[group]
            counters = _counters(shape, topic_id)
            starts = [get(counter, 0) for counter in counters]
            taken.update(zip(counters, [start + count for start in starts], strict=True))
            layout.append(starts)
        self._rows_per_column = taken  # vectors counted in their lengths column
        return layout

    def _slot_groups(self) -> dict[tuple[int, tuple[Any, ...]], list[tuple[int, int]]]:
        """Per leaf path: (group, first row) of every group with a slot on it, in group
        order (a vector's first row is in its lengths column). Built only when asked."""
        if self._by_path is None:
            self._by_path = {}
            for group, (topic_id, shape) in enumerate(self.shapes, start=1):
                keys = _plan(shape, topic_id)[0]
                for key, start in zip(keys, self._layout[group - 1], strict=True):
                    self._by_path.setdefault(key, []).append((group, start))
        return self._by_path

    def _shared_start(self, key: tuple[int, tuple[Any, ...]], group: int) -> int:
        """Where ``group`` starts in column ``key`` = (..., i), a column that scalar leaves
        (an array holding an object) and the i-th elements of vectors (an array of scalars
        elsewhere) may share: every earlier take of either kind, in group order."""
        topic_id, path = key
        index, parent = path[-1], (topic_id, path[:-1])
        length_key = (topic_id, (*path[:-1], LENGTHS))
        by_path = self._slot_groups()
        start = 0
        for earlier, _first in by_path.get(key, ()):
            if earlier < group and not self._is_vector_slot(earlier, key):
                start += self._counts[earlier]
        for earlier, first in by_path.get(parent, ()):
            wide_enough = earlier < group and self._is_vector_slot(earlier, parent)
            if wide_enough and self._cut(length_key, first, 1)[0] > index:
                start += self._counts[earlier]
        return start

    def _is_vector_slot(self, group: int, key: tuple[int, tuple[Any, ...]]) -> bool:
        _topic_id, shape = self.shapes[group - 1]
        return shape.paths.index(key[1]) in shape.vectors

    def _vectors(
        self, key: tuple[int, tuple[Any, ...]], start: int, count: int, group: int
    ) -> list[Any]:
        topic_id, path = key
        length_key = (topic_id, (*path, LENGTHS))
        lengths = self._cut(length_key, start, count)
        flat_key = (topic_id, (*path, FLAT))
        if flat_key in self._specs or flat_key in self._constants:
            before = self._flat_starts.get(length_key)
            if before is None:
                every = self._cut(length_key, 0, self._total(length_key))
                before = self._flat_starts[length_key] = [0, *accumulate(every)]
            flat = self._cut(flat_key, before[start], sum(lengths))
            ends = list(accumulate(lengths))
            return [flat[end - k : end] for k, end in zip(lengths, ends, strict=True)]
        width = lengths[0] if lengths else 0
        if lengths.count(width) != len(lengths):
            raise ColdFormatError("vectors of different lengths without a flat column")
        if width == 0:
            return [[] for _ in lengths]
        elements = []
        for i in range(width):
            element_key = (topic_id, (*path, i))
            # shared with scalar leaves (their takes counted apart) only if any exist
            shared = self._rows_per_column.get(element_key) and element_key not in self._constants
            at = self._shared_start(element_key, group) if shared else start
            elements.append(self._cut(element_key, at, count))
        return list(map(list, zip(*elements, strict=True)))

    def _total(self, key: tuple[int, tuple[Any, ...]]) -> int:
        """Rows in a lengths column (a constant one has one per row of its groups)."""
        if key in self._constants:
            return self._rows_per_column.get(key, 0)
        return len(self._column(key))

    def _group_rows(self, group: int) -> list[Sequence[Any]]:
        rows = self._rows.get(group)
        if rows is not None:
            return rows
        count = self._counts[group]
        _topic_id, shape = self.shapes[group - 1]
        vectors = shape.vectors
        columns = []
        topic_id = self.shapes[group - 1][0]
        keys = _plan(shape, topic_id)[0]
        for slot, (key, start) in enumerate(zip(keys, self._layout[group - 1], strict=True)):
            if slot in vectors:
                columns.append(self._vectors(key, start, count, group))
            else:
                # shared with vector elements only if the column holds more than the leaves
                shared = key in self._specs and len(self._column(key)) != self._rows_per_column[key]
                at = self._shared_start(key, group) if shared else start
                columns.append(self._cut(key, at, count))
        rows = self._rows[group] = list(zip(*columns, strict=True)) if columns else [()] * count
        return rows

    def messages(self, first: int, last: int) -> list[RawMessage]:
        """Messages ``first`` to ``last`` (positions in the block, inclusive), byte for byte."""
        if not 0 <= first <= last < self.n:
            raise ColdFormatError("a message range outside the block")
        needed = bytearray(self.n)
        needed[first : last + 1] = b"\x01" * (last + 1 - first)
        shape_ids, row_of, datas = self.shape_ids, self.row_of, self.datas
        # Digest references point back only: walking down from the end marks every
        # message the range depends on before any of them is built.
        for index in range(last, -1, -1):
            group = shape_ids[index]
            if not needed[index] or not group or datas[index] is not None:
                continue
            slots = self._slots_of_digests(group)
            if slots:
                row = self._group_rows(group)[row_of[index]]
                for slot in slots:
                    back = row[slot]
                    if type(back) is int:
                        if not 0 < back <= index:
                            raise ColdFormatError("a digest reference points outside the block")
                        needed[index - back] = 1
        dumps = orjson.dumps
        hexes: dict[int, str] = {}
        built: list[bytes] = datas  # type: ignore[assignment]  # refs only reach built ones
        for index in range(last + 1):
            if not needed[index] or datas[index] is not None:
                continue
            group = shape_ids[index]
            _topic_id, shape = self.shapes[group - 1]
            row = self._group_rows(group)[row_of[index]]
            slots = self._slots_of_digests(group)
            if slots:
                row = list(row)
                for slot in slots:
                    back = row[slot]
                    if type(back) is int:
                        row[slot] = _hex_of(built, hexes, index - back)
            build = shape.build if shape.compiled else shape.build_uncompiled
            datas[index] = dumps(build(row))
        names = self.topic_names
        return [
            RawMessage(names[self.topic_ids[i]], self.sequences[i], self.times[i], built[i])
            for i in range(first, last + 1)
        ]

    def _seals(self) -> list[int]:
        seal_id = self.topic_names.index(TOPIC_SEAL) if TOPIC_SEAL in self.topic_names else -1
        return [i for i, topic_id in enumerate(self.topic_ids) if topic_id == seal_id]

    @property
    def ends_sealed(self) -> bool:
        """Whether the block's last message is a seal: else an unsealed cycle ends it, whose
        time only assembling it tells (a seek then decodes the block whole)."""
        return self.n == 0 or self.topic_names[self.topic_ids[-1]] == TOPIC_SEAL

    def sealed_cycle_at(self, t_ns: int) -> tuple[int, int] | None:
        """The message range of the block's last sealed cycle at or before ``t_ns`` (its
        seal's log time), or None if there is none."""
        seals = self._seals()
        found = None
        for k, at in enumerate(seals):
            if self.times[at] <= t_ns:
                found = k
        if found is None:
            return None
        return (seals[found - 1] + 1 if found else 0), seals[found]


# --- blocks of cycles --------------------------------------------------------------------


def iter_blocks(messages: Iterable[RawMessage], block_cycles: int) -> Iterator[list[RawMessage]]:
    """Split a message stream into blocks of ``block_cycles`` sealed cycles each."""
    block: list[RawMessage] = []
    seals = 0
    for msg in messages:
        block.append(msg)
        if msg.topic == TOPIC_SEAL:
            seals += 1
            if seals == block_cycles:
                yield block
                block, seals = [], 0
    if block:
        yield block


def split_plain(
    block: Sequence[RawMessage],
) -> tuple[list[RawMessage], list[RawMessage], list[int]]:
    """(messages for the block, messages stored beside it, their positions in ``block``)."""
    kept: list[RawMessage] = []
    plain: list[RawMessage] = []
    positions: list[int] = []
    for position, msg in enumerate(block):
        if msg.topic in PLAIN_TOPICS:
            plain.append(msg)
            positions.append(position)
        else:
            kept.append(msg)
    return kept, plain, positions


def index_entry(block: Sequence[RawMessage]) -> dict[str, Any]:
    """The JSON index entry stored next to a block: counts and the chain anchors."""
    seals = [m for m in block if m.topic == TOPIC_SEAL]
    first = orjson.loads(seals[0].data) if seals else None
    last = orjson.loads(seals[-1].data) if seals else None
    return {
        "messages": len(block),
        "cycles": len(seals),
        "first_cycle": first.get("cycle") if isinstance(first, dict) else None,
        "last_cycle": last.get("cycle") if isinstance(last, dict) else None,
        "first_seal": hashlib.sha256(seals[0].data).hexdigest() if seals else None,
        "last_seal": hashlib.sha256(seals[-1].data).hexdigest() if seals else None,
    }


_INNER: dict[str, Assembler] = {"hot": assemble_hot, "warm": assemble_warm}
"""The tiers a cold block may hold the messages of (cold re-encodes a hot or a warm segment)."""


class BlockCache:
    """The last few decoded blocks: an investigation asks about nearby times (a decision, the
    cycles before it, their sensor readings) and each ask reads the block again. Keyed by
    the block's digest, so the same bytes share an entry. Thread-safe; owned by an assembler,
    so it lives as long as whoever holds that assembler (a reader, a compaction)."""

    def __init__(self, size: int = 4) -> None:
        if size < 0:
            raise ValueError("BlockCache size must not be negative")
        self.size = size
        self._blocks: OrderedDict[bytes, DecodedBlock | PartialBlock] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._blocks)

    def _get(self, key: bytes) -> DecodedBlock | PartialBlock | None:
        with self._lock:
            found = self._blocks.get(key)
            if found is not None:
                self._blocks.move_to_end(key)
            return found

    def _put(self, key: bytes, block: DecodedBlock | PartialBlock) -> None:
        with self._lock:
            self._blocks[key] = block
            while len(self._blocks) > self.size:
                self._blocks.popitem(last=False)

    def decode(self, data: bytes) -> DecodedBlock:
        """``decode_block(data)``, from the cache when it was decoded lately."""
        if self.size == 0:
            return decode_block(data)
        key = hashlib.sha256(data).digest()
        found = self._get(key)
        if isinstance(found, DecodedBlock):
            return found
        block = decode_block(data)
        self._put(key, block)
        return block

    def open(self, data: bytes) -> DecodedBlock | PartialBlock:
        """The block whole if it was decoded lately, else opened for a partial decode (kept,
        so a second seek into it reuses the columns and messages the first one built)."""
        key = hashlib.sha256(data).digest() if self.size else b""
        found = self._get(key) if self.size else None
        if found is not None:
            return found
        body = _block_body(data)
        with _malformed_as_format_error(), gc_paused():
            block = PartialBlock(body)
        if self.size:
            self._put(key, block)
        return block

    def clear(self) -> None:
        with self._lock:
            self._blocks.clear()


def assemble_cold(
    messages: Sequence[RawMessage], segment: str, cache: BlockCache | None = None
) -> list[Cycle]:
    """The reader's assembler for cold chunks: decode each block, assemble its cycles."""
    cycles: list[Cycle] = []
    for msg in messages:
        if msg.topic != BLOCK_TOPIC:
            continue
        try:
            block = cache.decode(msg.data) if cache is not None else decode_block(msg.data)
        except ColdFormatError as err:
            raise LogReadError(segment, f"cold block {msg.sequence}: {err}") from err
        assembler = _INNER.get(block.tier)
        if assembler is None:
            raise LogReadError(segment, f"cold block holds messages of unknown tier {block.tier!r}")
        cycles += assembler(block.messages, segment)
    return cycles


class ColdAssembler:
    """The reader's assembler for the cold tier: a cycle run ends with its block. It owns the
    cache of recently decoded blocks; make one per reader to bound the cache's lifetime."""

    closer_topic = BLOCK_TOPIC

    def __init__(self, cache_blocks: int = 4) -> None:
        self.cache = BlockCache(cache_blocks)

    def __call__(self, messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
        return assemble_cold(messages, segment, self.cache)

    def cycle_at(self, messages: Sequence[RawMessage], segment: str, t_ns: int) -> Cycle | None:
        """The last cycle of ``messages`` at or before ``t_ns`` (what ``__call__`` would give,
        filtered): a seek builds that one cycle, not the whole block."""
        for msg in reversed(messages):
            if msg.topic != BLOCK_TOPIC:
                continue
            try:
                found = self._block_cycle_at(msg.data, segment, t_ns)
            except ColdFormatError as err:
                raise LogReadError(segment, f"cold block {msg.sequence}: {err}") from err
            if found is not None:
                return found
        return None

    def _block_cycle_at(self, data: bytes, segment: str, t_ns: int) -> Cycle | None:
        block = self.cache.open(data)
        assembler = _INNER.get(block.tier)
        if assembler is None:
            raise LogReadError(segment, f"cold block holds messages of unknown tier {block.tier!r}")
        if isinstance(block, PartialBlock) and block.ends_sealed:
            with _malformed_as_format_error():
                span = block.sealed_cycle_at(t_ns)
                if span is None:
                    return None
                with gc_paused():
                    cycles = assembler(block.messages(*span), segment)
                if len(cycles) != 1:
                    raise ColdFormatError("a seal's message range is not one cycle")
                return cycles[0]
        if isinstance(block, PartialBlock):
            block = self.cache.decode(data)  # an unsealed cycle at the end: decode it whole
        matching = [c for c in assembler(block.messages, segment) if c.t_ns <= t_ns]
        return matching[-1] if matching else None


def iter_decoded(messages: Iterable[RawMessage]) -> Iterator[RawMessage]:
    """The original message stream behind a cold segment's messages, in the original order.

    ``messages`` is what ``Segment.iter_messages()`` gives for the whole segment: the plain
    messages of each chunk come before its block and are put back where they were.
    """
    beside: list[RawMessage] = []
    for msg in messages:
        if msg.topic == BLOCK_TOPIC:
            block = decode_block(msg.data)
            if len(block.plain) != len(beside):
                raise ColdFormatError("a block's plain messages are missing from its chunk")
            yield from merge_plain(block.messages, beside, block.plain)
            beside = []
        elif msg.topic in PLAIN_TOPICS:
            beside.append(msg)
        elif msg.topic != INDEX_TOPIC:
            yield msg
    yield from beside


def merge_plain(
    inner: list[RawMessage], plain: list[RawMessage], positions: list[int]
) -> Iterator[RawMessage]:
    """A block's messages with the plain ones put back at ``positions``."""
    pending = iter(inner)
    at = 0
    for position, msg in zip(positions, plain, strict=True):
        while at < position:
            yield next(pending)
            at += 1
        yield msg
        at += 1
    yield from pending
