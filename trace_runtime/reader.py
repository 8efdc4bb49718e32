"""The one reader of the TRACE format: segments, logs of many segments, cycles.

A finished segment is read through its summary: chunk indexes give the time range of every
chunk, so a question about one moment decodes one chunk. A segment without a summary (the
robot crashed, or the disk filled) is scanned linearly once, every complete record is kept,
and ``SegmentInfo.recovered`` says so.

How messages become cycles depends on the tier a segment is in (``trace.session`` metadata
``tier``): hot segments hold one message per layer and a seal per cycle; other tiers register
their own assembler with ``register_assembler``.
"""

from __future__ import annotations

import array
import bisect
import contextlib
import logging
import mmap
import os
import struct
import sys
import zlib
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Protocol

import orjson
import zstandard
from pydantic import ValidationError

from trace_runtime.chain import digest
from trace_runtime.errors import LogReadError, NotTraceLogError, TimeOutOfRangeError
from trace_runtime.records import (
    PROFILE,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_CHECKPOINT,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
    ActionMessage,
    BeliefMessage,
    ExecutionMessage,
    PerceptionMessage,
    Seal,
)
from trace_runtime.segment import CHUNK_TABLE_ATTACHMENT, MAGIC
from trace_runtime.session import SESSION_METADATA, SessionInfo

log = logging.getLogger("trace_runtime")

_RECORD_HEADER = struct.Struct("<BQ")
_MESSAGE_FIXED = struct.Struct("<HIQQ")
_CHUNK_FIXED = struct.Struct("<QQQI")
_FOOTER_SIZE = 9 + 20
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_CHUNK_INDEX, _OP_METADATA, _OP_DATA_END = 8, 12, 15
_OP_ATTACHMENT_INDEX, _OP_STATISTICS, _OP_METADATA_INDEX, _OP_SUMMARY_OFFSET = 10, 11, 13, 14
_MAX_RECORD = 1 << 34
_RECENT_CHUNKS = 4


# --- values ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RawMessage:
    """A message as stored: topic, per-channel sequence, log time, data."""

    topic: str
    sequence: int
    log_time_ns: int
    data: bytes


@dataclass(slots=True)
class Cycle:
    """One decision cycle as logged: its layer messages, seal and sensor readings.

    ``payloads`` maps a /trace topic to its canonical bytes. A warm-tier summary cycle has
    only the payloads that tier kept in full (at least the seal) and ``summary``: the pruned
    layer messages keyed by topic, shaped like the full JSON with the same field names.
    ``layer(topic)`` gives either, so analysis code reads both kinds of cycle alike.
    """

    cycle: int
    t_ns: int
    payloads: dict[str, bytes] = field(default_factory=dict)
    sensors: list[RawMessage] = field(default_factory=list)
    segment: str = ""
    summary: dict[str, Any] | None = None

    @property
    def sealed(self) -> bool:
        return TOPIC_SEAL in self.payloads

    @property
    def is_summary(self) -> bool:
        return self.summary is not None

    def json(self, topic: str) -> Any:
        """The full message on ``topic`` parsed as plain JSON, or None if absent."""
        data = self.payloads.get(topic)
        return None if data is None else orjson.loads(data)

    def layer(self, topic: str) -> Any:
        """The message on ``topic`` as JSON: the full one, else the warm summary's, else None."""
        data = self.payloads.get(topic)
        if data is not None:
            return orjson.loads(data)
        if self.summary is not None:
            return self.summary.get(topic)
        return None

    @property
    def seal(self) -> Seal | None:
        data = self.payloads.get(TOPIC_SEAL)
        return None if data is None else Seal.model_validate_json(data)

    @property
    def perception(self) -> PerceptionMessage | None:
        data = self.payloads.get(TOPIC_PERCEPTION)
        return None if data is None else PerceptionMessage.model_validate_json(data)

    @property
    def belief(self) -> BeliefMessage | None:
        data = self.payloads.get(TOPIC_BELIEF)
        return None if data is None else BeliefMessage.model_validate_json(data)

    @property
    def action(self) -> ActionMessage | None:
        data = self.payloads.get(TOPIC_ACTION)
        return None if data is None else ActionMessage.model_validate_json(data)

    @property
    def execution(self) -> ExecutionMessage | None:
        data = self.payloads.get(TOPIC_EXECUTION)
        return None if data is None else ExecutionMessage.model_validate_json(data)

    def digests(self) -> dict[str, str]:
        """SHA-256 of each layer payload present, keyed by topic (what a seal names)."""
        return {t: digest(d) for t, d in self.payloads.items() if t != TOPIC_SEAL}


@dataclass(frozen=True, slots=True)
class ChunkInfo:
    """Where a chunk is and what time it covers."""

    offset: int
    length: int
    start_ns: int
    end_ns: int


@dataclass(slots=True)
class SegmentInfo:
    """What a segment is, from its header, metadata and summary (or a scan)."""

    path: Path
    session: SessionInfo
    finished: bool
    recovered: bool
    start_ns: int
    end_ns: int
    message_count: int
    chunk_count: int
    channels: dict[str, int]
    bytes: int
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def tier(self) -> str:
        return self.session.tier


class Assembler(Protocol):
    """Turns the messages of one chunk (in file order) into cycles."""

    def __call__(self, messages: Sequence[RawMessage], segment: str) -> list[Cycle]: ...


# --- hot tier assembly ---------------------------------------------------------------------


def assemble_hot(messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
    """Group hot-tier messages into cycles: everything up to and including a seal.

    Messages after the last seal (a cycle the writer never sealed) become an unsealed cycle,
    numbered from their own ``cycle`` field, so nothing that was written is hidden.
    """
    cycles: list[Cycle] = []
    payloads: dict[str, bytes] = {}
    sensors: list[RawMessage] = []
    for msg in messages:
        if msg.topic == TOPIC_CHECKPOINT:
            continue  # a chain-head anchor, not part of any cycle (trace_runtime.integrity)
        if msg.topic.startswith("/trace/"):
            payloads[msg.topic] = msg.data
            if msg.topic == TOPIC_SEAL:
                cycles.append(Cycle(msg.sequence, msg.log_time_ns, payloads, sensors, segment))
                payloads, sensors = {}, []
        else:
            sensors.append(msg)
    if payloads:
        number = _cycle_field(next(iter(payloads.values())))
        t_ns = max(m.log_time_ns for m in messages if m.topic in payloads)
        cycles.append(Cycle(number, t_ns, payloads, sensors, segment))
    return cycles


def _cycle_field(data: bytes) -> int:
    """The ``cycle`` of an unsealed message, or -1 when its data does not say (damage)."""
    try:
        value = orjson.loads(data).get("cycle", -1)
        return value if type(value) is int else -1
    except (orjson.JSONDecodeError, AttributeError):
        return -1


_ASSEMBLERS: dict[str, Assembler] = {"hot": assemble_hot}


def register_assembler(tier: str, assembler: Assembler) -> None:
    """Teach the reader a tier: how that tier's messages become cycles."""
    _ASSEMBLERS[tier] = assembler


def _assembler_for(tier: str) -> Assembler:
    if tier not in _ASSEMBLERS:
        # Tier modules register themselves on import; importing here keeps the base reader
        # free of them until a segment of that tier is actually opened.
        import importlib

        with contextlib.suppress(ImportError):
            importlib.import_module("trace_runtime.tiers")
    return _ASSEMBLERS.get(tier, assemble_hot)


# --- one segment -----------------------------------------------------------------------------


class Segment:
    """A TRACE MCAP segment opened for reading."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._data = _map_file(self.path)
        if self._data[:8] != MAGIC:
            raise LogReadError(str(path), "not an MCAP file (bad magic)")
        self._schemas: dict[int, str] = {}
        self._topic_map: dict[int, str] = {}
        # Summary groups read only when needed (schemas and channels: when a chunk is
        # decoded; metadata: when asked for), so opening a segment reads a few records.
        self._deferred_summary: list[tuple[int, int]] = []
        self._metadata_at: dict[str, int] = {}
        # The chunk table: start times, end times and file offsets, sorted by start time.
        # Loaded lazily from the segment's own compact index (or the MCAP chunk indexes),
        # so opening a long segment does not pay for parsing tens of thousands of records.
        self._table: tuple[Sequence[int], Sequence[int], Sequence[int]] | None = None
        self._table_source: tuple[str, int, int] = ("none", 0, 0)
        self._ends_sorted = True
        self._statistics: tuple[int, int, int, dict[int, int]] | None = None
        self._loose: list[RawMessage] = []  # messages written outside chunks
        self._recent_chunks: OrderedDict[int, list[RawMessage]] = OrderedDict()
        self._metadata: dict[str, dict[str, str]] = {}
        self._decompressor = zstandard.ZstdDecompressor()
        self._profile = ""
        try:
            finished = self._read_summary()
        except _DAMAGE as err:
            # A damaged summary does not make the data unreadable: scan the data instead.
            log.warning("%s: damaged MCAP summary (%s); reading the data by scan", path, err)
            self._reset_index()
            finished = False
        if not finished:
            with _damage_as_read_error(self.path):
                self._scan()
        if self._profile != PROFILE:
            label = repr(self._profile) if self._profile else "none"
            raise NotTraceLogError(str(path), f"MCAP profile is {label}, not a TRACE log")
        if SESSION_METADATA not in self._metadata and SESSION_METADATA not in self._metadata_at:
            raise NotTraceLogError(str(path), "no trace.session metadata record")
        self.finished = finished
        self.start_ns: int
        self.end_ns: int
        if finished and self._statistics is not None:
            self.start_ns, self.end_ns = self._statistics[0], self._statistics[1]
        else:
            self.start_ns, self.end_ns = self.info.start_ns, self.info.end_ns
        if not finished:
            log.warning(
                "%s: no summary (unfinished segment); recovered %d complete messages by scan",
                self.path,
                self.info.message_count,
            )

    @property
    def _holds_messages(self) -> bool:
        """False for a segment with no chunk and no loose message (its times read 0)."""
        if self._loose:
            return True
        if self.finished and self._statistics is not None:
            return self._statistics[2] > 0
        return len(self._chunk_table()[0]) > 0

    def _reset_index(self) -> None:
        self._schemas.clear()
        self._topic_map.clear()
        self._deferred_summary.clear()
        self._metadata_at.clear()
        self._metadata.clear()
        self._table, self._table_source, self._statistics = None, ("none", 0, 0), None

    @cached_property
    def info(self) -> SegmentInfo:
        """What the segment is: session, time range, counts per channel, size, state."""
        return self._make_info(self.finished)

    @cached_property
    def session(self) -> SessionInfo:
        if SESSION_METADATA not in self._metadata:
            with _damage_as_read_error(self.path):
                self._parse_metadata_at(self._metadata_at[SESSION_METADATA])
        if SESSION_METADATA not in self._metadata:
            raise LogReadError(str(self.path), "the trace.session metadata record is damaged")
        try:
            return SessionInfo.from_metadata(self._metadata[SESSION_METADATA])
        except ValueError as err:  # a number field that is not a number
            raise LogReadError(str(self.path), f"damaged trace.session metadata ({err})") from err

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Every metadata record of the segment, by name."""
        for name, offset in self._metadata_at.items():
            if name not in self._metadata:
                self._parse_metadata_at(offset)
        return self._metadata

    @property
    def _topics(self) -> dict[int, str]:
        while self._deferred_summary:
            with _damage_as_read_error(self.path):
                self._parse_summary_records(*self._deferred_summary.pop())
        return self._topic_map

    @cached_property
    def _assemble(self) -> Assembler:
        return _assembler_for(self.session.tier)

    # --- summary and scan ------------------------------------------------------------

    def _read_summary(self) -> bool:
        data = self._data
        header = self._parse_header(8)
        if header is None:
            raise LogReadError(str(self.path), "truncated before the MCAP header ended")
        if len(data) < 8 + _FOOTER_SIZE + 8 or data[-8:] != MAGIC:
            return False
        footer_at = len(data) - 8 - _FOOTER_SIZE
        opcode, length = _RECORD_HEADER.unpack_from(data, footer_at)
        if opcode != _OP_FOOTER or length != 20:
            return False
        summary_start, offsets_start, _crc = struct.unpack_from("<QQI", data, footer_at + 9)
        if summary_start == 0:
            return False  # a finished file written without a summary: scan it
        ranges = self._summary_groups(offsets_start or footer_at, footer_at)
        if not ranges:  # no summary offsets: walk the whole summary section once
            ranges = {0: [(summary_start, offsets_start or footer_at)]}
        for opcode, spans in ranges.items():
            if opcode == _OP_CHUNK_INDEX:
                self._table_source = ("chunk_index", spans[0][0], spans[-1][1])
                continue
            if opcode in (_OP_SCHEMA, _OP_CHANNEL):
                self._deferred_summary += spans
                continue
            for begin, end in spans:
                self._parse_summary_records(begin, end)
        if self._table_source[0] == "none" and 0 in ranges:
            self._table_source = ("chunk_index", summary_start, offsets_start or footer_at)
        if not self._metadata and not self._metadata_at:
            return False
        if self._statistics is not None and self._statistics[2] == 0:
            # An unchunked file: its messages sit in the data section. (Its summary may still
            # hold an empty Chunk Index group, as the mcap library writes one.)
            self._scan_loose_messages()
        return True

    def _summary_groups(self, begin: int, end: int) -> dict[int, list[tuple[int, int]]]:
        """Summary Offset records: where each group of summary records lives."""
        groups: dict[int, list[tuple[int, int]]] = {}
        pos = begin
        while pos + 9 <= end:
            opcode, length = _RECORD_HEADER.unpack_from(self._data, pos)
            _check_fits(pos + 9, length, end)
            if opcode == _OP_SUMMARY_OFFSET:
                group, start, size = struct.unpack_from("<BQQ", self._data, pos + 9)
                _check_fits(start, size, len(self._data))
                groups.setdefault(group, []).append((start, start + size))
            pos += 9 + length
        return groups

    def _parse_summary_records(self, begin: int, end: int) -> None:
        data = self._data
        pos = begin
        while pos + 9 <= end:
            opcode, length = _RECORD_HEADER.unpack_from(data, pos)
            body = pos + 9
            _check_fits(body, length, end)
            if opcode == _OP_SCHEMA:
                self._parse_schema(body)
            elif opcode == _OP_CHANNEL:
                self._parse_channel(body)
            elif opcode == _OP_STATISTICS:
                self._parse_statistics(body)
            elif opcode == _OP_METADATA_INDEX:
                offset, _len = struct.unpack_from("<QQ", data, body)
                name, _ = _read_str(data, body + 16)
                self._metadata_at[name] = offset
            elif opcode == _OP_ATTACHMENT_INDEX:
                offset, _len, _log, _create, size = struct.unpack_from("<QQQQQ", data, body)
                name, _ = _read_str(data, body + 40)
                if name == CHUNK_TABLE_ATTACHMENT:
                    self._table_source = ("attachment", offset, size)
            pos = body + length

    def _parse_statistics(self, body: int) -> None:
        data = self._data
        (chunk_count,) = struct.unpack_from("<I", data, body + 8 + 2 + 4 + 4 + 4)
        start, end = struct.unpack_from("<QQ", data, body + 8 + 2 + 4 + 4 + 4 + 4)
        (map_len,) = struct.unpack_from("<I", data, body + 42)
        counts: dict[int, int] = {}
        pos = body + 46
        while pos < body + 46 + map_len:
            channel_id, n = struct.unpack_from("<HQ", data, pos)
            counts[channel_id] = n
            pos += 10
        self._statistics = (start, end, chunk_count, counts)

    # --- the chunk table -------------------------------------------------------------

    def _chunk_table(self) -> tuple[Sequence[int], Sequence[int], Sequence[int]]:
        if self._table is None:
            kind, first, second = self._table_source
            with _damage_as_read_error(self.path):
                if kind == "attachment":
                    self._load_table_attachment(first)
                elif kind == "chunk_index":
                    self._set_table(self._load_chunk_indexes(first, second))
                else:
                    self._set_table([])
        assert self._table is not None
        return self._table

    def _set_table(self, rows: list[tuple[int, int, int]]) -> None:
        self._set_columns([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows])

    def _set_columns(self, starts: list[int], ends: list[int], offsets: list[int]) -> None:
        # Timsort on sorted input is one linear pass in C: cheap enough to check every time.
        if starts != sorted(starts):
            rows = sorted(zip(starts, ends, offsets, strict=True))
            starts, ends, offsets = [r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows]
        self._ends_sorted = ends == sorted(ends)
        self._table = (starts, ends, offsets)

    def _load_table_attachment(self, offset: int) -> None:
        """Map the writer's chunk columns in place: no copy, no parse, already in order."""
        data = self._data
        pos = offset + 9 + 16
        _name, pos = _read_str(data, pos)
        _media, pos = _read_str(data, pos)
        (size,) = struct.unpack_from("<Q", data, pos)
        _check_fits(pos + 8, size, len(data))
        count = size // 24
        raw = memoryview(data)[pos + 8 : pos + 8 + 24 * count]
        if sys.byteorder == "big":
            values = array.array("Q", raw.tobytes())
            values.byteswap()
            raw = memoryview(values.tobytes())
        column = raw.cast("Q")
        self._table = (column[:count], column[count : 2 * count], column[2 * count :])
        self._ends_sorted = True

    def _load_chunk_indexes(self, begin: int, end: int) -> list[tuple[int, int, int]]:
        data = self._data
        rows = []
        pos = begin
        while pos + 9 <= end:
            opcode, length = _RECORD_HEADER.unpack_from(data, pos)
            if opcode == _OP_CHUNK_INDEX:
                start, stop, offset = struct.unpack_from("<QQQ", data, pos + 9)
                rows.append((start, stop, offset))
            pos += 9 + length
        return rows

    def _parse_header(self, pos: int) -> int | None:
        data = self._data
        if pos + 9 > len(data):
            return None
        opcode, length = _RECORD_HEADER.unpack_from(data, pos)
        if opcode != _OP_HEADER or pos + 9 + length > len(data):
            return None
        profile, _ = _read_str(data, pos + 9)
        self._profile = profile
        return int(pos + 9 + length)

    def _scan(self) -> None:
        """Walk every record after the header; stop at the first incomplete one."""
        rows: list[tuple[int, int, int]] = []
        data = self._data
        pos = self._parse_header(8) or len(data)
        end = len(data)
        while pos + 9 <= end:
            opcode, length = _RECORD_HEADER.unpack_from(data, pos)
            body = pos + 9
            if length > _MAX_RECORD or body + length > end:
                break  # a record cut short by the crash: everything before it is kept
            if opcode == _OP_SCHEMA:
                self._parse_schema(body)
            elif opcode == _OP_CHANNEL:
                self._parse_channel(body)
            elif opcode == _OP_METADATA:
                self._parse_metadata(body)
            elif opcode == _OP_CHUNK:
                start, stop = struct.unpack_from("<QQ", data, body)
                if self._chunk_valid(pos):
                    rows.append((start, stop, pos))
            elif opcode == _OP_MESSAGE:
                self._loose.append(self._parse_message(body, length, data))
            elif opcode in (_OP_DATA_END, _OP_FOOTER):
                break
            pos = body + length
        self._set_table(rows)

    def _scan_loose_messages(self) -> None:
        """Messages written outside chunks are not indexed; find them between chunks."""
        # Our writer never does this; other writers may. Cheap: skip over chunk records.
        data = self._data
        pos = self._parse_header(8) or len(data)
        while pos + 9 <= len(data):
            opcode, length = _RECORD_HEADER.unpack_from(data, pos)
            if opcode == _OP_MESSAGE:
                self._loose.append(self._parse_message(pos + 9, length, data))
            elif opcode == _OP_METADATA and SESSION_METADATA not in self._metadata:
                self._parse_metadata(pos + 9)
            elif opcode in (_OP_DATA_END, _OP_FOOTER) or length > _MAX_RECORD:
                break
            pos += 9 + length

    def _chunk_valid(self, pos: int) -> bool:
        try:
            self._decode_chunk_uncached(pos)
        except (LogReadError, *_DAMAGE):
            return False
        return True

    def _parse_schema(self, body: int) -> None:
        (schema_id,) = struct.unpack_from("<H", self._data, body)
        name, _ = _read_str(self._data, body + 2)
        self._schemas[schema_id] = name

    def _parse_channel(self, body: int) -> None:
        channel_id, _schema_id = struct.unpack_from("<HH", self._data, body)
        topic, _ = _read_str(self._data, body + 4)
        self._topic_map[channel_id] = topic

    def _parse_metadata_at(self, offset: int) -> None:
        opcode, _length = _RECORD_HEADER.unpack_from(self._data, offset)
        if opcode == _OP_METADATA:
            self._parse_metadata(offset + 9)

    def _parse_metadata(self, body: int) -> None:
        name, pos = _read_str(self._data, body)
        (map_len,) = struct.unpack_from("<I", self._data, pos)
        pos += 4
        stop = pos + map_len
        values: dict[str, str] = {}
        while pos < stop:
            key, pos = _read_str(self._data, pos)
            value, pos = _read_str(self._data, pos)
            values[key] = value
        self._metadata[name] = values

    def _parse_message(self, body: int, length: int, data: bytes) -> RawMessage:
        channel_id, sequence, log_time, _publish = _MESSAGE_FIXED.unpack_from(data, body)
        topic = self._topics.get(channel_id, f"<channel {channel_id}>")
        return RawMessage(topic, sequence, log_time, data[body + 22 : body + length])

    # --- chunks ----------------------------------------------------------------------------

    def _decode_chunk_at(self, offset: int) -> list[RawMessage]:
        """The messages of the chunk at ``offset``; the last few decoded are remembered, since
        an investigation asks about neighbouring moments (a seek, then a walk back)."""
        cached = self._recent_chunks.get(offset)
        if cached is not None:
            self._recent_chunks.move_to_end(offset)
            return cached
        with _damage_as_read_error(self.path):
            messages = self._decode_chunk_uncached(offset)
        self._recent_chunks[offset] = messages
        if len(self._recent_chunks) > _RECENT_CHUNKS:
            self._recent_chunks.popitem(last=False)
        return messages

    def _decode_chunk_uncached(self, offset: int) -> list[RawMessage]:
        data = self._data
        body = offset + 9
        _start, _end, size, crc = _CHUNK_FIXED.unpack_from(data, body)
        compression, pos = _read_str(data, body + 28)
        (records_len,) = struct.unpack_from("<Q", data, pos)
        pos += 8
        compressed = data[pos : pos + records_len]
        if compression == "zstd":
            raw = self._decompressor.decompress(compressed, max_output_size=size)
        elif compression == "":
            raw = compressed
        else:
            raise LogReadError(str(self.path), f"unsupported chunk compression {compression!r}")
        if crc and zlib.crc32(raw) != crc:
            raise LogReadError(str(self.path), f"chunk at offset {offset} fails its CRC")
        messages: list[RawMessage] = []
        topics = self._topics
        pos, end = 0, len(raw)
        while pos + 9 <= end:
            opcode, length = _RECORD_HEADER.unpack_from(raw, pos)
            body = pos + 9
            if opcode == _OP_MESSAGE:
                channel_id, sequence, log_time, _publish = _MESSAGE_FIXED.unpack_from(raw, body)
                messages.append(
                    RawMessage(
                        topics[channel_id], sequence, log_time, raw[body + 22 : body + length]
                    )
                )
            elif opcode == _OP_CHANNEL:
                self._parse_inner(raw, opcode, body)
            pos = body + length
        return messages

    def _parse_inner(self, raw: bytes, opcode: int, body: int) -> None:
        if opcode == _OP_CHANNEL:
            channel_id, _schema = struct.unpack_from("<HH", raw, body)
            topic, _ = _read_str(raw, body + 4)
            self._topic_map[channel_id] = topic

    def chunks(self) -> list[ChunkInfo]:
        """Every chunk's offset and time range, in time order."""
        starts, ends, offsets = self._chunk_table()
        return [ChunkInfo(o, 0, s, e) for s, e, o in zip(starts, ends, offsets, strict=True)]

    def iter_messages(
        self, start_ns: int | None = None, end_ns: int | None = None, *, reverse: bool = False
    ) -> Iterator[RawMessage]:
        """Raw messages with ``start_ns <= log_time <= end_ns``, in file order per chunk."""
        for messages in self._iter_chunk_messages(start_ns, end_ns, reverse=reverse):
            for msg in reversed(messages) if reverse else messages:
                if (start_ns is None or msg.log_time_ns >= start_ns) and (
                    end_ns is None or msg.log_time_ns <= end_ns
                ):
                    yield msg

    def _iter_chunk_messages(
        self, start_ns: int | None, end_ns: int | None, *, reverse: bool
    ) -> Iterator[list[RawMessage]]:
        starts, ends, offsets = self._chunk_table()
        hi = len(starts) if end_ns is None else bisect.bisect_right(starts, end_ns)
        lo = 0
        if start_ns is not None and self._ends_sorted:
            lo = bisect.bisect_left(ends, start_ns)
        chosen = [i for i in range(lo, hi) if start_ns is None or ends[i] >= start_ns]
        if self._loose and not reverse:
            yield self._loose
        for i in reversed(chosen) if reverse else chosen:
            yield self._decode_chunk_at(offsets[i])
        if self._loose and reverse:
            yield self._loose

    # --- cycles ----------------------------------------------------------------------------

    def iter_cycles(
        self, start_ns: int | None = None, end_ns: int | None = None, *, reverse: bool = False
    ) -> Iterator[Cycle]:
        """Cycles with ``start_ns <= t_ns <= end_ns``, oldest first (or newest first)."""
        name = self.path.name
        for messages in self._iter_chunk_messages(start_ns, end_ns, reverse=reverse):
            cycles = self._assemble(messages, name)
            for cycle in reversed(cycles) if reverse else cycles:
                if (start_ns is None or cycle.t_ns >= start_ns) and (
                    end_ns is None or cycle.t_ns <= end_ns
                ):
                    yield cycle

    def cycle_at(self, t_ns: int) -> Cycle | None:
        """The cycle in force at ``t_ns``: the last one at or before it (None if none)."""
        starts, _ends, offsets = self._chunk_table()
        index = bisect.bisect_right(starts, t_ns)
        # The chunk that starts last at or before t holds the answer unless t falls before
        # its first cycle: a chunk starts at its earliest sensor reading, which may precede
        # its cycle by several periods, and a closing checkpoint chunk holds no cycle. Step
        # back until a chunk has a cycle at or before t (a few chunks at most in practice).
        for i in range(index - 1, -1, -1):
            offset = offsets[i]
            cycles = [
                c
                for c in self._assemble(self._decode_chunk_at(offset), self.path.name)
                if c.t_ns <= t_ns
            ]
            if cycles:
                return cycles[-1]
        if self._loose:
            cycles = [c for c in self._assemble(self._loose, self.path.name) if c.t_ns <= t_ns]
            if cycles:
                return cycles[-1]
        return None

    def _make_info(self, finished: bool) -> SegmentInfo:
        channels: dict[str, int] = {}
        if finished and self._statistics is not None:
            start, end, chunk_count, counts = self._statistics
            channels = {self._topics.get(cid, str(cid)): n for cid, n in counts.items()}
        else:
            starts, ends, _offsets = self._chunk_table()
            start, end = min(starts, default=0), max(ends, default=0)
            for messages in self._iter_chunk_messages(None, None, reverse=False):
                for msg in messages:
                    channels[msg.topic] = channels.get(msg.topic, 0) + 1
            chunk_count = len(starts)
        if self._loose:
            times = [m.log_time_ns for m in self._loose]
            start = min(times) if not channels else min(start, *times)
            end = max(end, *times)
        return SegmentInfo(
            path=self.path,
            session=self.session,
            finished=finished,
            recovered=not finished,
            start_ns=start,
            end_ns=end,
            message_count=sum(channels.values()),
            chunk_count=chunk_count,
            channels=channels,
            bytes=len(self._data),
            metadata=dict(self.metadata),
        )


_DAMAGE = (struct.error, ValueError, KeyError, IndexError, OverflowError, zstandard.ZstdError)
"""What parsing a damaged record raises; never a bug of ours to show as a traceback."""


def _check_fits(body: int, length: int, end: int) -> None:
    """A record whose length runs past its section is damage, not a record."""
    if body + length > end:
        raise struct.error(
            f"record at {body - 9} runs {body + length - end} bytes past its section"
        )


@contextlib.contextmanager
def _damage_as_read_error(path: Path) -> Iterator[None]:
    try:
        yield
    except _DAMAGE as err:
        raise LogReadError(str(path), f"damaged MCAP record ({type(err).__name__}: {err})") from err


def _map_file(path: Path) -> bytes:
    """Map a segment read-only: seeks touch only the pages they read, however big the file."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if size == 0:
                raise LogReadError(str(path), "empty file")
            return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)  # type: ignore[return-value]
    except FileNotFoundError as err:
        raise LogReadError(str(path), "no such file") from err
    except IsADirectoryError as err:
        raise LogReadError(str(path), "is a directory, not a segment") from err
    except PermissionError as err:
        raise LogReadError(str(path), "permission denied") from err
    except OSError as err:
        raise LogReadError(str(path), f"cannot read ({err.strerror or err})") from err


def _read_str(data: bytes, pos: int) -> tuple[str, int]:
    (length,) = struct.unpack_from("<I", data, pos)
    start = pos + 4
    if start + length > len(data):
        raise struct.error("string runs past the end of the record")
    return data[start : start + length].decode("utf-8", errors="replace"), start + length


# --- a log of many segments ----------------------------------------------------------------


class Log:
    """One or more segments read as one log, ordered by time (across tiers)."""

    def __init__(self, segments: Sequence[Segment], root: Path) -> None:
        if not segments:
            raise LogReadError(str(root), "no TRACE segments found")
        self.root = root
        kept, self.shadowed = _one_copy_per_segment(segments)
        self.segments = sorted(kept, key=lambda s: (s.start_ns, s.path.name))
        self._starts = [s.start_ns for s in self.segments]
        # A segment that holds nothing (a logger opened and closed without a cycle) has no
        # time range; its zeros must not stretch the log's range back to the epoch.
        self._timed = [s for s in self.segments if s._holds_messages] or self.segments

    @property
    def start_ns(self) -> int:
        return min(s.start_ns for s in self._timed)

    @property
    def end_ns(self) -> int:
        return max(s.end_ns for s in self._timed)

    @property
    def recovered(self) -> bool:
        return any(not s.finished for s in self.segments)

    def iter_cycles(
        self, start_ns: int | None = None, end_ns: int | None = None, *, reverse: bool = False
    ) -> Iterator[Cycle]:
        """Every cycle in time order across segments (or newest first)."""
        segments = [
            s
            for s in self.segments
            if (start_ns is None or s.end_ns >= start_ns)
            and (end_ns is None or s.start_ns <= end_ns)
        ]
        for segment in reversed(segments) if reverse else segments:
            yield from segment.iter_cycles(start_ns, end_ns, reverse=reverse)

    def cycle_at(self, t_ns: int) -> Cycle:
        """The cycle in force at ``t_ns``; ``TimeOutOfRangeError`` outside the log's range."""
        if t_ns < self.start_ns or t_ns > self.end_ns + max(
            (s.session.period_ns for s in self.segments), default=0
        ):
            raise TimeOutOfRangeError(t_ns, self.start_ns, self.end_ns)
        index = bisect.bisect_right(self._starts, t_ns)
        for segment in reversed(self.segments[:index]):
            found = segment.cycle_at(t_ns)
            if found is not None:
                return found
        raise TimeOutOfRangeError(t_ns, self.start_ns, self.end_ns)

    def get_cycle(self, number: int) -> Cycle | None:
        """The cycle with this number (a scan bounded to the segment that covers it)."""
        for segment in self.segments:
            first = segment.session.first_cycle
            if number < first:
                continue
            for cycle in segment.iter_cycles():
                if cycle.cycle == number:
                    return cycle
                if cycle.cycle > number:
                    break
        return None


_TIER_ORDER = {"hot": 0, "warm": 1, "cold": 2}


def _one_copy_per_segment(segments: Sequence[Segment]) -> tuple[list[Segment], list[Segment]]:
    """While a compaction runs (or after one was interrupted) a segment can sit in two tiers
    of a root. Keep the least compacted copy of each; return (kept, shadowed). Only roots
    with a warm/ or cold/ directory in use are compared, so a hot-only log opens no metadata.
    """
    if not any(s.path.parent.name in ("warm", "cold") for s in segments):
        return list(segments), []
    chosen: dict[tuple[str, int, int, str], Segment] = {}
    kept: list[Segment] = []
    shadowed: list[Segment] = []
    for segment in segments:
        session = segment.session
        key = (session.robot_id, session.segment, session.first_cycle, session.prev_seal)
        other = chosen.get(key)
        if other is None:
            chosen[key] = segment
        elif other.session.tier == session.tier:
            kept.append(segment)  # two files of one tier: different content, keep both
        elif _TIER_ORDER.get(session.tier, 9) < _TIER_ORDER.get(other.session.tier, 9):
            shadowed.append(other)
            chosen[key] = segment
        else:
            shadowed.append(segment)
    return kept + list(chosen.values()), shadowed


SegmentOpener = Callable[[Path], Segment]


def find_segments(path: Path) -> list[Path]:
    """Segment files of a log: the file itself, or every ``*.mcap`` below a directory."""
    if path.is_dir():
        return sorted(p for p in path.rglob("*.mcap") if p.is_file() and ".partial" not in p.name)
    return [path]


def open_segment(path: str | Path) -> Segment:
    """Open one segment file; raises ``LogReadError`` / ``NotTraceLogError``."""
    return Segment(path)


def open_log(path: str | Path) -> Log:
    """Open a segment file, a directory of segments, or a log root (hot/ warm/ cold/)."""
    root = Path(path)
    if not root.exists():
        raise LogReadError(str(root), "no such file or directory")
    files = find_segments(root)
    if not files:
        raise LogReadError(str(root), "directory holds no .mcap segments")
    return Log([Segment(p) for p in files], root)


def last_seal(path: Path) -> tuple[Seal, str] | None:
    """The last readable seal in a segment and its digest (to continue a chain after a
    restart). Damage never stops a robot from logging: a damaged seal is passed over, and a
    segment that cannot be read gives None (the caller then tries an older one; `verify`
    reports the resulting break)."""
    try:
        segment = Segment(path)
        for cycle in segment.iter_cycles(reverse=True):
            data = cycle.payloads.get(TOPIC_SEAL)
            if data is None:
                continue
            try:
                return Seal.model_validate_json(data), digest(data)
            except ValidationError:
                continue
    except LogReadError:
        return None
    return None
