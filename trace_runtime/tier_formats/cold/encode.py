"""Encoding a block: each JSON message split into a shape and its leaf values, the values of
one leaf path across the block made a column, each column given the cheapest exact coding
that fits it, and the whole block compressed with zstd.

Column codings: one constant, delta-coded integers, decimals as delta-coded scaled integers,
raw doubles, dictionary-coded strings, or, for SHA-256 hex strings that are the digest of an
earlier message of the block (seal digests, ``prev``, evidence ref digests), a
back-reference to that message. Messages that are not canonical compact JSON are stored
verbatim, so any input round-trips; every block is decoded again before it is returned.
"""

from __future__ import annotations

import hashlib
import struct
from array import array
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from itertools import chain, repeat
from operator import mul, truediv
from typing import Any

import orjson
import zstandard

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError, ShapeError
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tier_formats.cold.cache import BlockCache
from trace_runtime.tier_formats.cold.columns import (
    SCALES,
    le_bytes,
    pack_i64,
    pack_small,
    pack_stream,
    shuffle,
)
from trace_runtime.tier_formats.cold.decode import DecodedBlock
from trace_runtime.tier_formats.cold.format import (
    BOOL,
    CONST,
    DEC,
    DEFAULT_LEVEL,
    DIGEST,
    F64,
    FLAT,
    INT,
    JSON,
    LENGTHS,
    MAGIC,
    NULLABLE,
    SENSORS,
    STR,
    ColumnKey,
    gc_paused,
)
from trace_runtime.tier_formats.cold.sensors import SENSOR_DIGEST_PATH, SensorCovers
from trace_runtime.tier_formats.shapes import SHAPE_CACHE_LIMIT, Shape, describe

SEAL_ANCHOR_CYCLES = 64
"""Every this-many-th seal of a block keeps its ``prev`` digest as a literal instead of a
back-reference (~0.5 byte a cycle at 64): a seek then rebuilds the hash chain from the
nearest such anchor, not from the start of the block (``PartialBlock``); readers need not
know it. Measured on a 2 h sim log: a seek 2.7-2.9x faster than a whole-block decode with
anchors every 32 or 64 cycles (the fixed cost of opening a block dominates), 1.4x
without; 64 costs half the bytes of 32 (+0.5 vs +1.15 B a cycle)."""
_SEAL_PREV = (TOPIC_SEAL, ("prev",))
_SEAL_SENSORS = (TOPIC_SEAL, SENSOR_DIGEST_PATH)
_MAX_NEW_SHAPES_PER_TOPIC = 64
_NEG_ZERO = struct.pack("<d", -0.0)
_DEC_TRIES = 10
_MISMATCH = (KeyError, IndexError, TypeError, AttributeError)


@dataclass(slots=True)
class _Column:
    """The values of one (topic, leaf path) across a block and where they came from.

    ``groups`` lists the shape groups whose rows the values are, in order; it is None for
    the element columns of vectors, whose values are not one per row.
    """

    values: list[Any] = field(default_factory=list)
    groups: list[int] | None = field(default_factory=list)


def _add_vectors(
    columns: dict[ColumnKey, _Column],
    key: ColumnKey,
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
    columns: dict[ColumnKey, _Column],
    key: ColumnKey,
    values: Iterable[Any],
) -> None:
    column = columns.get(key)
    if column is None:
        column = columns[key] = _Column(groups=None)
    column.groups = None  # shared with a vector's elements: no longer one value per row
    column.values += values


@dataclass(slots=True)
class _Grouped:
    """A block's messages sorted into shape groups: per message its topic id, shape group
    (0: stored verbatim) and sequence delta; per group its rows and message positions; and
    the SHA-256 hex of every message (with the first position of each digest)."""

    topics: dict[str, int] = field(default_factory=dict)
    topic_ids: list[int] = field(default_factory=list)
    shape_ids: list[int] = field(default_factory=list)
    seq_deltas: list[int] = field(default_factory=list)
    raw: list[bytes] = field(default_factory=list)
    group_rows: list[list[tuple[Any, ...]]] = field(default_factory=list)
    group_msgs: list[list[int]] = field(default_factory=list)
    group_keys: list[tuple[int, Shape]] = field(default_factory=list)
    digests: dict[str, int] = field(default_factory=dict)
    digest_list: list[str] = field(default_factory=list)


class BlockEncoder:
    """Encodes blocks of messages; keeps shapes and per-column hints from block to block.

    It owns the ``BlockCache`` its blocks are decoded with for the check, so the check
    finds the very shapes (and compiled code) the encoder made.
    """

    def __init__(self, level: int = DEFAULT_LEVEL) -> None:
        self._zstd = zstandard.ZstdCompressor(level=level)
        self._checker = BlockCache(0)
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
                decoded = self._checker.decode_checked(data, self._last_digests)
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
        grouped = self._group(messages, verbatim=verbatim)
        self._last_raw = len(grouped.raw)
        self._last_digests = grouped.digest_list
        topic_names = list(grouped.topics)

        def covers() -> SensorCovers:
            sequences = [m.sequence for m in messages]
            times = [m.log_time_ns for m in messages]
            return SensorCovers(topic_names, grouped.topic_ids, sequences, times)

        payload: list[bytes] = []
        col_headers: list[list[Any]] = []
        for (topic_id, path), column in _columns(grouped).items():
            hint_key = (topic_names[topic_id], path)
            codec, param, body = self._encode_column(column, hint_key, grouped, covers)
            payload.append(body)
            col_headers.append([topic_id, list(path), codec, len(body), param])
        raw = grouped.raw
        topic_code, topic_body = pack_small(grouped.topic_ids)
        shape_code, shape_body = pack_small(grouped.shape_ids)
        fixed = [
            topic_body,
            shape_body,
            pack_stream(grouped.seq_deltas, delta=False),
            pack_stream([m.log_time_ns for m in messages], delta=True),
            pack_i64([len(r) for r in raw], delta=False) or b"",
            b"".join(raw),
        ]
        header = {
            "tier": tier,
            "n": len(messages),
            "topics": topic_names,
            # descriptors as JSON text: a decoder looks its compiled shape up by these bytes
            "shapes": [[t, s.key.decode()] for t, s in grouped.group_keys],
            "msg": [topic_code, shape_code, *(len(b) for b in fixed)],
            "cols": col_headers,
            "plain": list(plain),
        }
        head = orjson.dumps(header)
        body = b"".join([struct.pack("<I", len(head)), head, *fixed, *payload])
        return MAGIC + self._zstd.compress(body)

    def _group(self, messages: Sequence[RawMessage], *, verbatim: bool) -> _Grouped:
        """Sort a block's messages into shape groups (``verbatim``: every one stored as is)."""
        out = _Grouped()
        topics, topic_ids, shape_ids, raw = out.topics, out.topic_ids, out.shape_ids, out.raw
        group_rows, group_msgs, group_keys = out.group_rows, out.group_msgs, out.group_keys
        groups: dict[tuple[int, Shape], int] = {}
        new_shapes: Counter[str] = Counter()
        last_seq: dict[int, int] = {}
        sha256, loads = hashlib.sha256, orjson.loads
        for index, msg in enumerate(messages):
            topic_id = topics.setdefault(msg.topic, len(topics))
            topic_ids.append(topic_id)
            out.seq_deltas.append(msg.sequence - last_seq.get(topic_id, 0))
            last_seq[topic_id] = msg.sequence
            data = msg.data
            digest = sha256(data).hexdigest()
            out.digest_list.append(digest)
            out.digests.setdefault(digest, index)
            shape: Shape | None = None
            row: tuple[Any, ...] = ()
            try:
                value = None if verbatim else loads(data)
            except orjson.JSONDecodeError:
                value = None
            if type(value) is dict or type(value) is list:
                shape, row = self._match(msg, value, new_shapes)
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
        return out

    def _match(
        self, msg: RawMessage, value: Any, new_shapes: Counter[str]
    ) -> tuple[Shape | None, tuple[Any, ...]]:
        """The shape a parsed JSON message is coded with and its row of leaves, or None when
        it is stored verbatim (no shape fits, or the message is not canonical JSON)."""
        data = msg.data
        # Candidate shapes are found by the message's count of objects and arrays: one dict
        # lookup, and a shape that would take a container for a scalar (valid, but coded
        # poorly) is never even tried.
        sig = (msg.topic, data.count(b"{"), data.count(b"["))
        shape: Shape | None = None
        row: tuple[Any, ...] = ()
        for candidate in self._by_sig.get(sig, ()):
            try:
                row = candidate.extract_row(value)
            except _MISMATCH:
                continue
            shape = candidate
            break
        if shape is None and new_shapes[msg.topic] < _MAX_NEW_SHAPES_PER_TOPIC:
            shape = self._new_shape(value)
            if shape is not None:
                new_shapes[msg.topic] += 1
                row = shape.extract_row(value)
                if len(self._by_sig) >= SHAPE_CACHE_LIMIT:
                    self._by_sig.clear()
                self._by_sig.setdefault(sig, []).insert(0, shape)
        if shape is not None and (self._strict or msg.topic in self._noncanonical):
            try:
                canonical = orjson.dumps(value) == data
            except orjson.JSONEncodeError:
                canonical = False
            if not canonical:
                self._noncanonical.add(msg.topic)
                return None, ()
        return shape, row

    def _new_shape(self, value: Any) -> Shape | None:
        try:
            descriptor = describe(value)
        except ShapeError:
            return None
        return self._checker.shapes.shape(descriptor, orjson.dumps(descriptor))

    def _encode_column(
        self,
        column: _Column,
        hint_key: tuple[str, tuple[Any, ...]],
        grouped: _Grouped,
        covers: Callable[[], SensorCovers],
    ) -> tuple[str, Any, bytes]:
        values = column.values
        types = set(map(type, values))
        if types <= {str, type(None)} and str in types:
            if values.count(values[0]) == len(values):
                return CONST, values[0], b""
            if hint_key == _SEAL_SENSORS and types == {str}:
                at_rows = _message_indexes(column, grouped.group_msgs)
                if at_rows is not None:
                    derived = _encode_sensors(values, at_rows, covers(), grouped.digest_list)
                    if derived is not None:
                        return derived
            anchored = SEAL_ANCHOR_CYCLES if hint_key == _SEAL_PREV else 0
            return _encode_strings(
                values,
                grouped.digests,
                lambda: _message_indexes(column, grouped.group_msgs),
                anchored,
            )
        if len(types) == 2 and type(None) in types:
            kind = (types - {type(None)}).pop()
            if kind is float or kind is int or kind is bool:
                # Nullable numbers: a presence mask, and the numbers coded as a column.
                mask = bytes([v is not None for v in values])
                present = [v for v in values if v is not None]
                codec, param, body = self._encode_typed(kind, present, hint_key)
                return NULLABLE, [codec, param, len(mask)], mask + body
        if len(types) == 1:
            return self._encode_typed(types.pop(), values, hint_key)
        return JSON, None, orjson.dumps(values)

    def _encode_typed(
        self, kind: type, values: list[Any], hint_key: tuple[str, tuple[Any, ...]]
    ) -> tuple[str, Any, bytes]:
        """A column whose values all have type ``kind`` (and are not strings)."""
        n = len(values)
        if kind is float:
            raw = le_bytes(array("d", values))
            if raw == raw[:8] * n:
                return CONST, values[0], b""
            return self._encode_floats(values, raw, hint_key)
        if values.count(values[0]) == n:
            return CONST, values[0], b""
        if kind is int:
            packed = pack_i64(values, delta=True)
            if packed is not None:
                return INT, None, packed
        elif kind is bool:
            return BOOL, None, bytes(values)
        return JSON, None, orjson.dumps(values)

    def _encode_floats(
        self, values: list[float], raw: bytes, hint_key: tuple[str, tuple[Any, ...]]
    ) -> tuple[str, Any, bytes]:
        hint = self._hints.get(hint_key)
        if hint != -1:
            # -0.0 == 0.0, so the check below cannot see a lost sign: list where they were.
            negative_zeros = _negative_zeros(values, raw)
            tries = range(_DEC_TRIES) if hint is None else (hint, *range(_DEC_TRIES))
            for k in tries:
                scale = SCALES[k]
                try:
                    ints = list(map(round, map(mul, values, repeat(scale))))
                except OverflowError:  # beyond the float range once scaled: not a decimal
                    break
                if list(map(truediv, ints, repeat(scale))) == values:
                    packed = pack_i64(ints, delta=True)
                    if packed is not None:
                        self._hints[hint_key] = k
                        return DEC, [k, negative_zeros], packed
        self._hints[hint_key] = -1
        return F64, None, shuffle(raw, 8)


def _columns(grouped: _Grouped) -> dict[ColumnKey, _Column]:
    """The block's columns, one per (topic, leaf path), in the order the decoder takes them:
    scalar leaves group by group, then each vector leaf's lengths and elements."""
    columns: dict[ColumnKey, _Column] = {}
    vector_values: dict[ColumnKey, list[list[Any]]] = {}
    for group, (topic_id, shape) in enumerate(grouped.group_keys):
        vectors = shape.vectors
        slots = zip(*grouped.group_rows[group], strict=True)
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
    return columns


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


def _encode_sensors(
    values: list[str], at_rows: list[int], covers: SensorCovers, digests: list[str]
) -> tuple[str, Any, bytes] | None:
    """Seals' sensors digests as flags (1: derived from the block) and the literals that
    are not; None if none is derived."""
    flags, literals = covers.derived(values, at_rows, digests)
    if len(literals) == len(values):
        return None
    return SENSORS, [literals], flags


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
        code, body = pack_small(offsets)
        return DIGEST, [code, literals], body
    table = list(dict.fromkeys(values))
    position = {s: i for i, s in enumerate(table)}
    code, body = pack_small(list(map(position.__getitem__, values)))
    return STR, [code, table], body
