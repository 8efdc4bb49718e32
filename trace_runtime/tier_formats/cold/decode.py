"""Decoding a whole block: its header and message streams, every column, and every message
rebuilt byte for byte from its shape and row, digest back-references resolved.

A block's body (decompressed by its ``BlockCache``, which also owns the shapes) starts with
a header, then the per-message streams (topic, shape, sequence delta, log time delta, the
lengths and bytes of the messages no shape describes), then the column bodies. Every size
the header declares is checked against the body before it is used, and what the block
rebuilds is charged to its ``BuildBudget`` as it is built.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from itertools import accumulate, repeat
from typing import Any

import orjson

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError
from trace_runtime.tier_formats.cold.columns import (
    decode_column,
    plan,
    unpack_i64,
    unpack_small,
    unpack_stream,
)
from trace_runtime.tier_formats.cold.format import (
    CONST,
    FLAT,
    LENGTHS,
    REFERENCES,
    SENSORS,
    BuildBudget,
    ColumnKey,
)
from trace_runtime.tier_formats.cold.sensors import DERIVED, SensorCovers
from trace_runtime.tier_formats.shapes import Shape, ShapeCache


@dataclass(frozen=True, slots=True)
class DecodedBlock:
    """A block's messages as they were, the tier they assemble as, and where the messages
    stored beside the block (``PLAIN_TOPICS``) go back in."""

    tier: str
    messages: list[RawMessage]
    plain: list[int]


@dataclass(slots=True)
class BlockStreams:
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

    def covers(self) -> SensorCovers:
        """Which messages are each cycle's readings (for derived sensors digests)."""
        return SensorCovers(self.topic_names, self.topic_ids, self.sequences, self.times)

    @classmethod
    def read(cls, body: bytes, cache: ShapeCache) -> BlockStreams:
        """The header and message streams of ``body``; its shapes looked up in ``cache``."""
        (head_len,) = struct.unpack_from("<I", body, 0)
        pos = fitting(4, head_len, len(body))
        header = orjson.loads(memoryview(body)[4:pos])  # read in place, not copied
        n = int(header["n"])
        topic_code, shape_code, *sizes = header["msg"]
        parts: list[bytes] = []
        for size in sizes:
            parts.append(body[pos : fitting(pos, size, len(body))])
            pos += size
        topic_body, shape_body, seq_body, time_body, raw_len_body, raw_body = parts
        topic_ids = unpack_small(topic_code, topic_body)
        shape_ids = unpack_small(shape_code, shape_body)
        seq_deltas = unpack_stream(seq_body, delta=False)
        times = unpack_stream(time_body, delta=True)
        raw_lens = unpack_i64(raw_len_body, delta=False) if raw_len_body else []
        if sum(raw_lens) != len(raw_body) or min(raw_lens, default=0) < 0:
            raise ColdFormatError("the raw messages' lengths disagree with their bytes")
        if not (len(topic_ids) == len(shape_ids) == len(seq_deltas) == len(times) == n):
            raise ColdFormatError("message streams disagree on the message count")
        shapes = [
            (int(topic_id), cache.shape_of(text.encode())) for topic_id, text in header["shapes"]
        ]
        topic_names = [str(t) for t in header["topics"]]
        return cls(
            header,
            n,
            topic_names,
            topic_ids,
            shape_ids,
            _sequences(topic_ids, seq_deltas),
            times,
            raw_lens,
            raw_body,
            shapes,
            pos,
        )


def fitting(pos: int, size: Any, end: int) -> int:
    """Where a stream or column of ``size`` bytes at ``pos`` ends, if it lies in the body."""
    if type(size) is not int or size < 0 or pos + size > end:
        raise ColdFormatError(f"a stream or column of {size!r} bytes does not fit in the block")
    return pos + size


def _sequences(topic_ids: list[int], seq_deltas: list[int]) -> list[int]:
    """Each message's sequence number: the deltas run per topic."""
    sequences: list[int] = []
    last_seq: dict[int, int] = {}
    for topic_id, delta in zip(topic_ids, seq_deltas, strict=True):
        last_seq[topic_id] = sequence = last_seq.get(topic_id, 0) + delta
        sequences.append(sequence)
    return sequences


def decode_body(
    body: bytes,
    cache: ShapeCache,
    known_digests: dict[int, str] | None = None,
    budget: BuildBudget | None = None,
) -> DecodedBlock:
    """A block body's messages, refused once they pass ``budget`` (by default, what the
    default ``ReadLimits`` allow); ``known_digests`` (message position -> SHA-256 hex) is
    only ever the encoder's check (``BlockCache.decode_checked``)."""
    budget = budget if budget is not None else BuildBudget.within()
    streams = BlockStreams.read(body, cache)
    header, n, shapes = streams.header, streams.n, streams.shapes
    reader = _read_columns(body, header, streams.columns_at, budget)
    positions: list[list[int]] = [[] for _ in range(len(shapes) + 1)]
    for index, group in enumerate(streams.shape_ids):
        positions[group].append(index)
    if len(positions) != len(shapes) + 1:
        raise ColdFormatError("a message names a shape the block does not have")
    datas: list[bytes] = [b""] * n
    raw_at = 0
    for index, size in zip(positions[0], streams.raw_lens, strict=True):
        datas[index] = streams.raw_body[raw_at : raw_at + size]
        raw_at += size
    budget.spend(len(streams.raw_body))
    built = bytearray(n)
    for index in positions[0]:
        built[index] = 1
    waiting = _build_plain_groups(shapes, positions, reader, datas, built, budget=budget)
    hexes: dict[int, str] = known_digests if known_digests is not None else {}
    refs = _References(datas, built, hexes, streams.covers() if reader.covers else None, budget)
    _build_waiting_groups(waiting, positions, refs, budget=budget)
    topics = list(map(streams.topic_names.__getitem__, streams.topic_ids))
    messages = list(map(RawMessage, topics, streams.sequences, streams.times, datas))
    plain = [int(p) for p in header.get("plain", [])]
    return DecodedBlock(str(header["tier"]), messages, plain)


def _read_columns(
    body: bytes, header: dict[str, Any], pos: int, budget: BuildBudget
) -> _ColumnReader:
    """Every column of the block decoded, from the header's column table."""
    reader = _ColumnReader(budget)
    for topic_id, path, codec, size, param in header["cols"]:
        key = (int(topic_id), tuple(path))
        end = fitting(pos, size, len(body))
        if codec == CONST:
            reader.constants[key] = param  # no body: one value, repeated for every row
        else:
            reader.columns[key] = decode_column(codec, param, body[pos:end])
        if codec in REFERENCES:
            reader.digests.add(key)
        reader.covers = reader.covers or codec == SENSORS
        pos += size
    return reader


_Waiting = tuple[int, Shape, list[Sequence[Any]], list[int]]
"""A shape group whose rows hold digest references: (group, shape, rows, digest slots)."""


def _build_plain_groups(
    shapes: list[tuple[int, Shape]],
    positions: list[list[int]],
    reader: _ColumnReader,
    datas: list[bytes],
    built: bytearray,
    *,
    budget: BuildBudget,
) -> list[_Waiting]:
    """Build, in bulk, the messages of every shape group without digest references; return
    the groups that have them.

    A shape whose leaves hold digests of earlier messages (seals, evidence refs) can be
    built only once those messages are, so those wait for ``_build_waiting_groups``. Each
    message's bytes are charged to ``budget`` as it is built.
    """
    dumps = orjson.dumps
    spend = budget.spend
    waiting: list[_Waiting] = []
    for group, (topic_id, shape) in enumerate(shapes, start=1):
        count = len(positions[group])
        keys, vectors = plan(shape, topic_id)
        slices = reader.take_all(keys, vectors, count)
        rows: Iterable[Sequence[Any]] = zip(*slices, strict=True) if slices else repeat((), count)
        slots = [i for i, key in enumerate(keys) if key in reader.digests] if reader.digests else []
        if slots:
            waiting.append((group, shape, list(rows), slots))
            continue
        build = _builder(shape, count, budget)
        for index, data in zip(positions[group], map(dumps, map(build, rows)), strict=True):
            spend(len(data))
            datas[index] = data
            built[index] = 1
    return waiting


def _builder(shape: Shape, messages: int, budget: BuildBudget) -> Callable[[Any], Any]:
    """How ``messages`` messages of ``shape`` are built: with its compiled code (compiling
    charged to ``budget``) once the shape is used enough for compiling to pay, else by
    walking its descriptor. A group of no messages (only a hostile block declares one) is
    compiled, and charged, as any shape a block names."""
    if not messages or shape.worth_compiling(messages):
        return budget.compiled(shape)
    return shape.walk_build


def _build_waiting_groups(
    waiting: list[_Waiting],
    positions: list[list[int]],
    refs: _References,
    *,
    budget: BuildBudget,
) -> None:
    """Build the groups with digest references: each group whose targets are all built
    (refs to sensor readings) in bulk; what is left (seals, which name the previous seal)
    in message order. Each message's bytes are charged to ``budget``."""
    dumps = orjson.dumps
    spend = budget.spend
    datas, built = refs.datas, refs.built
    sequential = []
    for group, shape, rows_list, slots in waiting:
        filled = _fill_digests(positions[group], rows_list, slots, refs)
        if filled is None:
            sequential.append((group, shape, iter(rows_list), slots))
            continue
        build = _builder(shape, len(filled), budget)
        for index, data in zip(positions[group], map(dumps, map(build, filled)), strict=True):
            spend(len(data))
            datas[index] = data
            built[index] = 1
    if sequential:
        order = sorted((i, entry) for entry in sequential for i in positions[entry[0]])
        for index, (_group, shape, rows_left, digest_slots) in order:
            row = list(next(rows_left))
            for slot in digest_slots:
                # in message order, every message before this one is built
                resolved = refs.resolve(index, row[slot])
                if resolved is _UNBUILT:
                    raise ColdFormatError("a digest reference points at an unbuilt message")
                row[slot] = resolved
            data = datas[index] = dumps(_builder(shape, 1, budget)(row))
            built[index] = 1
            spend(len(data))


class _ColumnReader:
    """Hands out the next values of each decoded column, shape group by shape group; a
    constant's repetitions are charged to ``budget`` before they are made."""

    def __init__(self, budget: BuildBudget) -> None:
        self.budget = budget
        self.columns: dict[ColumnKey, list[Any]] = {}
        self.constants: dict[ColumnKey, Any] = {}
        self.digests: set[ColumnKey] = set()
        self.covers = False
        """Whether a column holds derived sensors digests."""
        self._taken: dict[ColumnKey, int] = {}

    def take(self, key: ColumnKey, count: int) -> list[Any]:
        if key in self.constants:
            return self.budget.repeat(self.constants[key], count)
        values = self.columns[key]
        start = self._taken.get(key, 0)
        if start + count > len(values):
            raise ColdFormatError("a column is shorter than its shapes need")
        self._taken[key] = start + count
        return values[start : start + count]

    def take_all(self, keys: list[ColumnKey], vectors: list[bool], count: int) -> list[list[Any]]:
        """``take`` (or ``take_vectors``) of every key of a shape group, in one call: a
        block has hundreds of groups times dozens of keys, and this is the decoder's loop."""
        columns, constants, taken = self.columns, self.constants, self._taken
        repeat_constant = self.budget.repeat
        out: list[list[Any]] = []
        for key, vector in zip(keys, vectors, strict=True):
            if vector:
                out.append(self.take_vectors(key, count))
            elif key in constants:
                out.append(repeat_constant(constants[key], count))
            else:
                values = columns[key]
                start = taken.get(key, 0)
                end = start + count
                if end > len(values):
                    raise ColdFormatError("a column is shorter than its shapes need")
                taken[key] = end
                out.append(values[start:end])
        return out

    def take_vectors(self, key: ColumnKey, count: int) -> list[Any]:
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


def _fill_digests(
    positions: list[int], rows: list[Sequence[Any]], slots: list[int], refs: _References
) -> list[Sequence[Any]] | None:
    """Rows with their digest references resolved, or None if one points at an unbuilt message."""
    out: list[Sequence[Any]] = []
    resolve = refs.resolve
    for index, row in zip(positions, rows, strict=True):
        fixed = list(row)
        for slot in slots:
            resolved = resolve(index, fixed[slot])
            if resolved is _UNBUILT:
                return None
            fixed[slot] = resolved
        out.append(fixed)
    return out


_UNBUILT = object()
"""What a reference resolves to while the message it names is not built yet."""


class _References:
    """Resolves the values of a block's reference columns as its messages are built: a
    back-reference (an int) to the digest of the message it points at, a derived sensors
    digest (``DERIVED``) to the cover of its cycle's readings; a literal is itself."""

    __slots__ = ("budget", "built", "covers", "datas", "hexes")

    def __init__(
        self,
        datas: list[bytes],
        built: bytearray,
        hexes: dict[int, str],
        covers: SensorCovers | None,
        budget: BuildBudget,
    ) -> None:
        self.datas, self.built, self.hexes = datas, built, hexes
        self.covers, self.budget = covers, budget

    def resolve(self, index: int, value: Any) -> Any:
        """``value`` at message ``index`` resolved, or ``_UNBUILT`` while what it names is
        not built yet (a literal may be null)."""
        if type(value) is int:
            at = index - value
            if at >= 0 and not self.built[at]:
                return _UNBUILT
            return hex_of(self.datas, self.hexes, at)  # refused there if before the block
        if value is DERIVED and self.covers is not None:
            cover = self.covers.cover(index, self._digest_if_built, self.budget.spend)
            return _UNBUILT if cover is None else cover
        return value

    def _digest_if_built(self, at: int) -> str | None:
        return hex_of(self.datas, self.hexes, at) if self.built[at] else None


def hex_of(datas: list[bytes], cache: dict[int, str], at: int) -> str:
    if at < 0:
        raise ColdFormatError("a digest reference points before the block")
    value = cache.get(at)
    if value is None:
        value = cache[at] = hashlib.sha256(datas[at]).hexdigest()
    return value
