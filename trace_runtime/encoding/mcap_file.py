"""The byte layer of the reader: one MCAP file as records, chunks and messages.

It knows MCAP and nothing of TRACE: the header, the summary (or a linear scan when a crashed
writer left none), metadata records, the chunk table, and decoding a chunk into messages.
Every read is bounded, because an investigator opens files an attacker may have prepared:
``ReadLimits`` caps a chunk's decompressed size (declared and real), the records a chunk may
hold for its compressed size, record lengths and string lengths; a limit hit is a
``LogLimitError`` (a ``LogReadError``), never a ``MemoryError`` or a hang. The record framing
is ``mcap_records``, one chunk's decoding ``mcap_chunks``, the bounds ``read_limits``.
"""

from __future__ import annotations

import array
import bisect
import contextlib
import itertools
import logging
import struct
import sys
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_chunks import ChunkDecoder
from trace_runtime.encoding.mcap_records import (
    CHUNK_TABLE_ATTACHMENT,
    DAMAGE,
    FOOTER_SIZE,
    MAGIC,
    MESSAGE_FIXED,
    OP_ATTACHMENT_INDEX,
    OP_CHANNEL,
    OP_CHUNK,
    OP_CHUNK_INDEX,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_METADATA,
    OP_METADATA_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
    OP_SUMMARY_OFFSET,
    RECORD_HEADER,
    check_fits,
    damage_reason,
    map_file,
    read_str,
)
from trace_runtime.errors import LogLimitError, LogReadError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits

log = logging.getLogger("trace_runtime")

_RECENT_CHUNKS = 4


@dataclass(frozen=True, slots=True)
class ChunkInfo:
    """Where a chunk is and what time it covers."""

    offset: int
    length: int
    start_ns: int
    end_ns: int


class McapFile:
    """An MCAP file opened for reading: records, metadata, chunk table, messages."""

    def __init__(self, path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        self.path = Path(path)
        self.limits = limits
        self._data = map_file(self.path)
        if self._data[:8] != MAGIC:
            raise LogReadError(str(path), "not an MCAP file (bad magic)")
        self.profile = ""
        self._schemas: dict[int, str] = {}
        self._topic_map: dict[int, str] = {}
        # Summary groups read only when needed (schemas and channels: when a chunk is
        # decoded; metadata: when asked for), so opening a file reads a few records.
        self._deferred_summary: list[tuple[int, int]] = []
        self._metadata_at: dict[str, list[int]] = {}
        self._metadata: dict[str, list[dict[str, str]]] = {}
        # The chunk table: start times, end times and file offsets, sorted by start time.
        # Loaded lazily from the writer's compact index (or the MCAP chunk indexes), so
        # opening a long file does not pay for parsing tens of thousands of records.
        self._table: tuple[Sequence[int], Sequence[int], Sequence[int]] | None = None
        self._index_spans: list[tuple[int, int]] = []  # where the Chunk Index records are
        self._attachment_at: int | None = None  # our trace.chunk_columns attachment
        self._ends_sorted = True
        self._starts_in_file_order = True
        self._sorted_offsets: list[int] | None = None
        self.statistics: tuple[int, int, int, dict[int, int]] | None = None
        """(message start ns, message end ns, chunk count, messages per channel id)."""
        self._loose: list[RawMessage] = []
        self.summarized = False
        """Whether the summary section was read (its indexes are hints, checked when used)."""
        self.notes: list[str] = []
        """Indexes of the file that were not used because they disagree with its data."""
        self.skipped_chunks: list[tuple[int, str]] = []
        """Damaged chunks stepped over, by a scan or when read: (file offset, why)."""
        self._damaged: set[int] = set()
        self._recent_chunks: OrderedDict[int, list[RawMessage]] = OrderedDict()
        self._chunks = ChunkDecoder(self.path, limits)
        with self.damage_as_read_error():
            self.finished = self._has_footer()
        """Whether the file ends in a footer: its writer closed it (with a summary or not)."""
        try:
            self.summarized = self.finished and self._read_summary()
        except DAMAGE as err:
            # A damaged summary does not make the data unreadable: scan the data instead.
            log.warning("%s: damaged MCAP summary (%s); reading the data by scan", path, err)
            self._reset_index()
            self.summarized = False
        with self.damage_as_read_error():
            if not self.summarized:
                self._walk_data(chunks=True, decode=True)
            elif (not self._metadata and not self._metadata_at) or (
                self.statistics is not None and self.statistics[2] == 0
            ):
                # No Metadata Index (an optional summary group), or an unchunked file (its
                # summary may still hold an empty Chunk Index group, as the mcap library
                # writes one): the metadata records or the messages are in the data section.
                self._walk_data(chunks=False)

    @property
    def size(self) -> int:
        return len(self._data)

    @property
    def loose(self) -> list[RawMessage]:
        """Messages written outside chunks (some writers do; ours never). Looked for in the
        data section whenever no chunk index is there to use, as the reference readers do."""
        self.chunk_table()
        return self._loose

    @property
    def holds_messages(self) -> bool:
        """False for a file with no chunk and no loose message (its times read 0)."""
        return bool(self.loose) or len(self.chunk_table()[0]) > 0

    def trusted_statistics(self) -> tuple[int, int, int, dict[str, int]] | None:
        """The summary's Statistics (start ns, end ns, chunks, messages per topic) when they
        agree with the chunks found and name only known channels; None to count by reading."""
        if not self.summarized or self.statistics is None:
            return None
        starts = self.chunk_table()[0]
        start, end, chunk_count, counts = self.statistics
        topics = self.topics
        if chunk_count != len(starts):
            return None
        if any(cid not in topics for cid in counts):
            return None  # channels only inside chunks: the counts cannot be named
        return start, end, chunk_count, {topics[cid]: n for cid, n in counts.items()}

    def _reset_index(self) -> None:
        self._schemas.clear()
        self._topic_map.clear()
        self._deferred_summary.clear()
        self._metadata_at.clear()
        self._metadata.clear()
        self._table, self.statistics, self._attachment_at = None, None, None
        self._index_spans.clear()

    @contextlib.contextmanager
    def damage_as_read_error(self) -> Iterator[None]:
        """Turn what parsing damaged bytes raises into one ``LogReadError`` naming the file."""
        try:
            yield
        except DAMAGE as err:
            raise LogReadError(str(self.path), damage_reason(err)) from err

    # --- metadata --------------------------------------------------------------------------

    def metadata_records(self, name: str) -> list[dict[str, str]]:
        """Every metadata record called ``name``, in file order (usually one)."""
        for offset in self._metadata_at.pop(name, []):
            with self.damage_as_read_error():
                self._parse_metadata_at(offset)
        return self._metadata.get(name, [])

    def has_metadata(self, name: str) -> bool:
        return name in self._metadata or name in self._metadata_at

    @property
    def metadata(self) -> dict[str, dict[str, str]]:
        """Every metadata record by name (the last one of a name, as MCAP tools show it)."""
        for name in list(self._metadata_at):
            self.metadata_records(name)
        return {name: records[-1] for name, records in self._metadata.items() if records}

    @property
    def topics(self) -> dict[int, str]:
        """Channel id to topic."""
        while self._deferred_summary:
            with self.damage_as_read_error():
                self._parse_summary_records(*self._deferred_summary.pop())
        return self._topic_map

    # --- summary and scan ------------------------------------------------------------------

    def _has_footer(self) -> bool:
        data = self._data
        if self._parse_header(8) is None:
            raise LogReadError(str(self.path), "truncated before the MCAP header ended")
        if len(data) < 8 + FOOTER_SIZE + 8 or data[-8:] != MAGIC:
            return False
        opcode, length = RECORD_HEADER.unpack_from(data, len(data) - 8 - FOOTER_SIZE)
        return bool(opcode == OP_FOOTER and length == 20)

    def _read_summary(self) -> bool:
        """Read the summary section a footer points at; False when there is none."""
        data = self._data
        footer_at = len(data) - 8 - FOOTER_SIZE
        summary_start, offsets_start, _crc = struct.unpack_from("<QQI", data, footer_at + 9)
        if summary_start == 0:
            return False  # a finished file written without a summary: scan it
        check_fits(summary_start, 0, footer_at)
        ranges = self._summary_groups(offsets_start or footer_at, footer_at)
        if OP_CHUNK_INDEX not in ranges:
            # No summary offsets, or none for the Chunk Indexes (a file without chunks, or a
            # writer that did not point at them): walk the whole summary section once.
            ranges = {0: [(summary_start, offsets_start or footer_at)]}
        for opcode, spans in ranges.items():
            if opcode == OP_CHUNK_INDEX:
                self._index_spans += spans
                continue
            if opcode in (OP_SCHEMA, OP_CHANNEL):
                self._deferred_summary += spans
                continue
            for begin, end in spans:
                self._parse_summary_records(begin, end)
        if 0 in ranges:
            self._index_spans = ranges[0]
        return True

    def _summary_groups(self, begin: int, end: int) -> dict[int, list[tuple[int, int]]]:
        """Summary Offset records: where each group of summary records lives."""
        groups: dict[int, list[tuple[int, int]]] = {}
        pos = begin
        while pos + 9 <= end:
            opcode, length = RECORD_HEADER.unpack_from(self._data, pos)
            check_fits(pos + 9, length, end)
            if opcode == OP_SUMMARY_OFFSET:
                group, start, size = struct.unpack_from("<BQQ", self._data, pos + 9)
                check_fits(start, size, len(self._data))
                groups.setdefault(group, []).append((start, start + size))
            pos += 9 + length
        return groups

    def _parse_summary_records(self, begin: int, end: int) -> None:
        data = self._data
        pos = begin
        while pos + 9 <= end:
            opcode, length = RECORD_HEADER.unpack_from(data, pos)
            body = pos + 9
            check_fits(body, length, end)
            if opcode == OP_SCHEMA:
                self._parse_schema(body)
            elif opcode == OP_CHANNEL:
                self._parse_channel(body)
            elif opcode == OP_STATISTICS:
                self._parse_statistics(body)
            elif opcode == OP_METADATA_INDEX:
                offset, _len = struct.unpack_from("<QQ", data, body)
                name, _ = read_str(data, body + 16)
                self._metadata_at.setdefault(name, []).append(offset)
            elif opcode == OP_ATTACHMENT_INDEX:
                offset, _len, _log, _create, _size = struct.unpack_from("<QQQQQ", data, body)
                name, _ = read_str(data, body + 40)
                if name == CHUNK_TABLE_ATTACHMENT:
                    self._attachment_at = offset
            pos = body + length

    def _parse_statistics(self, body: int) -> None:
        data = self._data
        (chunk_count,) = struct.unpack_from("<I", data, body + 8 + 2 + 4 + 4 + 4)
        start, end = struct.unpack_from("<QQ", data, body + 8 + 2 + 4 + 4 + 4 + 4)
        (map_len,) = struct.unpack_from("<I", data, body + 42)
        counts: dict[int, int] = {}
        pos = body + 46
        check_fits(pos, map_len, len(data))
        while pos < body + 46 + map_len:
            channel_id, n = struct.unpack_from("<HQ", data, pos)
            counts[channel_id] = n
            pos += 10
        self.statistics = (start, end, chunk_count, counts)

    def _parse_header(self, pos: int) -> int | None:
        data = self._data
        if pos + 9 > len(data):
            return None
        opcode, length = RECORD_HEADER.unpack_from(data, pos)
        if opcode != OP_HEADER or pos + 9 + length > len(data):
            return None
        profile, _ = read_str(data, pos + 9)
        self.profile = profile
        return int(pos + 9 + length)

    def _walk_data(self, *, chunks: bool, decode: bool = False) -> None:
        """Walk the data section's records, stopping at the first incomplete one (a record a
        crash cut short: everything before it is kept): the messages written outside chunks,
        the metadata when no index names it, and (with ``chunks``) every chunk's place and
        time range. ``decode`` (a file without a summary) decodes each chunk met, so that
        damage is known before the table is used; otherwise it is found when a chunk is read."""
        data = self._data
        rows: list[tuple[int, int, int]] = []
        want_metadata = not self._metadata and not self._metadata_at
        self._loose.clear()
        pos = self._parse_header(8) or len(data)
        while pos + 9 <= len(data):
            opcode, length = RECORD_HEADER.unpack_from(data, pos)
            body = pos + 9
            if length > self.limits.max_record_bytes or body + length > len(data):
                break
            if opcode == OP_MESSAGE:
                self._loose.append(self._parse_message(body, length, data))
            elif opcode == OP_CHUNK and chunks:
                start, stop = struct.unpack_from("<QQ", data, body)
                # A damaged chunk stays in the table (its time range says where the damage
                # is) but reads as empty; the walk goes on to the next complete record.
                rows.append((start, stop, pos))
                damage = self._chunk_damage(pos) if decode else None
                if damage is not None:
                    self._skip_chunk(pos, damage)
            elif opcode == OP_SCHEMA:
                self._parse_schema(body)
            elif opcode == OP_CHANNEL:
                self._parse_channel(body)
            elif opcode == OP_METADATA and want_metadata:
                self._parse_metadata(body)
            elif opcode in (OP_DATA_END, OP_FOOTER):
                break
            pos = body + length
        if chunks:
            self._set_table(rows)

    def _chunk_damage(self, pos: int) -> str | None:
        """Why a chunk met in a scan does not decode (None if it does); a limit hit is not
        damage to step over: it is raised, and the file is refused."""
        try:
            self._decode_chunk_uncached(pos)
        except LogLimitError:
            raise
        except LogReadError as err:
            return err.reason
        except DAMAGE as err:
            return f"chunk at offset {pos} is damaged ({type(err).__name__}: {err})"
        return None

    def _parse_schema(self, body: int) -> None:
        (schema_id,) = struct.unpack_from("<H", self._data, body)
        name, _ = read_str(self._data, body + 2)
        self._schemas[schema_id] = name

    def _parse_channel(self, body: int) -> None:
        channel_id, _schema_id = struct.unpack_from("<HH", self._data, body)
        topic, _ = read_str(self._data, body + 4)
        self._topic_map[channel_id] = topic

    def _parse_metadata_at(self, offset: int) -> None:
        opcode, length = RECORD_HEADER.unpack_from(self._data, offset)
        check_fits(offset + 9, length, len(self._data))
        if opcode == OP_METADATA:
            self._parse_metadata(offset + 9)

    def _parse_metadata(self, body: int) -> None:
        name, pos = read_str(self._data, body)
        (map_len,) = struct.unpack_from("<I", self._data, pos)
        pos += 4
        stop = pos + map_len
        check_fits(pos, map_len, len(self._data))
        values: dict[str, str] = {}
        while pos < stop:
            key, pos = read_str(self._data, pos)
            value, pos = read_str(self._data, pos)
            values[key] = value
        self._metadata.setdefault(name, []).append(values)

    def _parse_message(self, body: int, length: int, data: bytes) -> RawMessage:
        channel_id, sequence, log_time, _publish = MESSAGE_FIXED.unpack_from(data, body)
        topic = self.topics.get(channel_id, f"<channel {channel_id}>")
        return RawMessage(topic, sequence, log_time, data[body + 22 : body + length])

    # --- the chunk table -------------------------------------------------------------------

    def chunk_table(self) -> tuple[Sequence[int], Sequence[int], Sequence[int]]:
        """(start ns, end ns, file offset) columns of every chunk, sorted by start time."""
        if self._table is None:
            with self.damage_as_read_error():
                self._resolve_table()
        assert self._table is not None
        return self._table

    def _resolve_table(self) -> None:
        """The chunk table from the first index that agrees with the data: our attachment,
        then the Chunk Index records, then a walk of the data section. Every index is a hint:
        one that disagrees is noted and the next is tried, so no tool that kept a stale copy
        of it, dropped it or never wrote it changes what is read."""
        expected = None if self.statistics is None else self.statistics[2]
        if self._attachment_at is not None:
            why = self._load_table_attachment(self._attachment_at, expected)
            if why is None:
                return
            self._note(f"its {CHUNK_TABLE_ATTACHMENT} attachment is not used: {why}")
        if self._index_spans:
            rows = [row for span in self._index_spans for row in self._load_chunk_indexes(*span)]
            why = self._rows_disagree(rows, expected)
            if why is None and (rows or expected == 0):
                self._set_table(rows)
                return
            if why is not None:
                self._note(f"its Chunk Index records are not used: {why}")
        elif expected == 0:
            self._set_table([])  # no chunks, says the summary; loose messages were walked
            return
        self._walk_data(chunks=True)

    def _note(self, text: str) -> None:
        self.notes.append(text)
        log.info("%s: %s; the chunks are found another way", self.path, text)

    def _rows_disagree(self, rows: list[tuple[int, int, int]], expected: int | None) -> str | None:
        """Why Chunk Index rows do not describe this file's chunks (None when they do)."""
        if expected is not None and len({r[2] for r in rows}) != expected:
            return f"{len(rows)} of them for the {expected} chunks its Statistics count"
        for start, stop, offset in rows:
            if not self._chunk_at(offset, start, stop):
                return f"the one for offset {offset} does not point at a chunk of its times"
        return None

    def _chunk_at(self, offset: int, start_ns: int, end_ns: int) -> bool:
        """Whether a chunk record with this time range starts at ``offset``."""
        data = self._data
        return (
            offset + 25 <= len(data)
            and data[offset] == OP_CHUNK
            and struct.unpack_from("<QQ", data, offset + 9) == (start_ns, end_ns)
        )

    def _set_table(self, rows: list[tuple[int, int, int]]) -> None:
        # Sorted by start time for seeks; chunks that start together stay in file order.
        # (Timsort on sorted input is one linear pass in C: cheap enough to check always.)
        # One row per chunk: an index naming a chunk twice would make every read repeat it.
        by_time = sorted({r[2]: r for r in rows}.values(), key=lambda r: (r[0], r[2]))
        starts, ends = [r[0] for r in by_time], [r[1] for r in by_time]
        offsets = [r[2] for r in by_time]
        self._ends_sorted = ends == sorted(ends)
        self._starts_in_file_order = offsets == sorted(offsets)
        self._table = (starts, ends, offsets)

    def _load_table_attachment(self, offset: int, expected: int | None) -> str | None:
        """Map the writer's chunk columns in place: no copy, no parse, already in order.
        Returns why they do not describe this file (None when they were loaded)."""
        data = self._data
        pos = offset + 9 + 16
        _name, pos = read_str(data, pos)
        _media, pos = read_str(data, pos)
        (size,) = struct.unpack_from("<Q", data, pos)
        check_fits(pos + 8, size, len(data))
        count = size // 24
        if size % 24 or (expected is not None and count != expected):
            return f"it lists {count} chunks, the file's Statistics {expected}"
        raw = memoryview(data)[pos + 8 : pos + 8 + 24 * count]
        if sys.byteorder == "big":
            values = array.array("Q", raw.tobytes())
            values.byteswap()
            raw = memoryview(values.tobytes())
        column = raw.cast("Q")
        offsets = column[2 * count :]
        # Ours is written in file order, each chunk once. Checked at a bounded sample of
        # places, so that opening a long segment stays free of a pass over its table (a
        # table that lies elsewhere costs at most a re-read of chunks it names, and the
        # chunks themselves are checked when read).
        # A copy kept by a tool that rewrote the file (the mcap CLI keeps attachments) names
        # the old file's offsets: at a sampled place, no chunk of those times is there.
        places = sorted({*range(0, count, max(1, count // 64)), count - 1} - {-1})
        sample = [offsets[i] for i in places]
        if any(b <= a for a, b in itertools.pairwise(sample)):
            return "its chunks are not in file order"
        for i in places:
            if not self._chunk_at(offsets[i], column[i], column[count + i]):
                return (
                    f"no chunk of the times it lists at offset {offsets[i]} (a copy of "
                    "another file's)"
                )
        self._table = (column[:count], column[count : 2 * count], offsets)
        # Our writer's own table: written in file order, one chunk per batch in time order.
        self._ends_sorted = self._starts_in_file_order = True
        return None

    def _load_chunk_indexes(self, begin: int, end: int) -> list[tuple[int, int, int]]:
        data = self._data
        rows = []
        pos = begin
        while pos + 9 <= end:
            opcode, length = RECORD_HEADER.unpack_from(data, pos)
            if opcode == OP_CHUNK_INDEX:
                start, stop, offset = struct.unpack_from("<QQQ", data, pos + 9)
                rows.append((start, stop, offset))
            pos += 9 + length
        return rows

    def chunks(self) -> list[ChunkInfo]:
        """Every chunk's offset and time range, in time order."""
        starts, ends, offsets = self.chunk_table()
        return [ChunkInfo(o, 0, s, e) for s, e, o in zip(starts, ends, offsets, strict=True)]

    def offsets_in_range(self, start_ns: int | None, end_ns: int | None) -> list[int]:
        """File offsets of the chunks that may hold messages in the range, in file order."""
        starts, ends, offsets = self.chunk_table()
        hi = len(starts) if end_ns is None else bisect.bisect_right(starts, end_ns)
        lo = 0
        if start_ns is not None and self._ends_sorted:
            lo = bisect.bisect_left(ends, start_ns)
        chosen = [offsets[i] for i in range(lo, hi) if start_ns is None or ends[i] >= start_ns]
        return chosen if self._starts_in_file_order else sorted(chosen)

    def offsets_back_from(self, t_ns: int) -> Iterator[int]:
        """File offsets of the chunks that start at or before ``t_ns``, the latest start
        first: a seek looks at one or two of them, so they are produced one at a time."""
        starts, _ends, offsets = self.chunk_table()
        for i in range(bisect.bisect_right(starts, t_ns) - 1, -1, -1):
            yield offsets[i]

    def previous_offset(self, offset: int) -> int | None:
        """The chunk just before the one at ``offset`` in the file (None for the first)."""
        order = self._file_order()
        i = bisect.bisect_left(order, offset)
        return order[i - 1] if i > 0 else None

    def is_last_chunk(self, offset: int) -> bool:
        order = self._file_order()
        return bool(order) and order[-1] == offset

    def _file_order(self) -> Sequence[int]:
        offsets = self.chunk_table()[2]
        if self._starts_in_file_order:
            return offsets
        if self._sorted_offsets is None:
            self._sorted_offsets = sorted(offsets)
        return self._sorted_offsets

    # --- chunks ----------------------------------------------------------------------------

    def chunk_messages(self, offset: int) -> list[RawMessage]:
        """The messages of the chunk at file ``offset``; the last few decoded are remembered,
        since an investigation asks about neighbouring moments (a seek, then a walk back).

        A chunk that is damaged (fails its CRC, does not decompress, holds broken records)
        gives no messages: it is recorded in ``skipped_chunks``, a warning is logged once,
        and every other chunk is still read. A limit hit is not damage: it is raised.
        """
        cached = self._recent_chunks.get(offset)
        if cached is not None:
            self._recent_chunks.move_to_end(offset)
            return cached
        messages = self._decode_or_skip(offset, None)
        if offset in self._damaged:
            return messages
        self._recent_chunks[offset] = messages
        if len(self._recent_chunks) > _RECENT_CHUNKS:
            self._recent_chunks.popitem(last=False)
        return messages

    def _decode_or_skip(self, offset: int, only: str | None) -> list[RawMessage]:
        """The chunk's messages (``only``: on that topic), or none for a damaged chunk,
        recorded in ``skipped_chunks`` (a limit hit is raised)."""
        if offset in self._damaged:
            return []
        try:
            if only is None:
                return self._decode_chunk_uncached(offset)
            return self._chunks.decode(self._data, offset, self.topics, only)
        except LogLimitError:
            raise
        except LogReadError as err:
            self._skip_chunk(offset, err.reason)
        except DAMAGE as err:
            # What ``damage_as_read_error`` would say, without entering a context manager
            # for every chunk read (a chunk a cycle).
            self._skip_chunk(offset, damage_reason(err))
        return []

    def topic_messages(self, topic: str) -> Iterator[RawMessage]:
        """``[m for m in iter_messages() if m.topic == topic]``, one at a time, without
        building the other messages: every chunk is still decoded and checked, and a
        damaged one is skipped and recorded as ``chunk_messages`` does (a pass over a file
        for one rare topic, e.g. its checkpoints, before its cycles are read)."""
        for message in self.loose:
            if message.topic == topic:
                yield message
        for offset in self.offsets_in_range(None, None):
            cached = self._recent_chunks.get(offset)
            if cached is not None:
                self._recent_chunks.move_to_end(offset)
                yield from (m for m in cached if m.topic == topic)
            else:
                yield from self._decode_or_skip(offset, topic)

    def clear_caches(self) -> None:
        """Forget the recently decoded chunks (to measure a first read)."""
        self._recent_chunks.clear()

    def is_damaged(self, offset: int) -> bool:
        """Whether the chunk at ``offset`` was found damaged (once it has been read)."""
        return offset in self._damaged

    def _skip_chunk(self, offset: int, reason: str) -> None:
        if f"offset {offset}" not in reason:
            reason = f"chunk at offset {offset}: {reason}"
        self._damaged.add(offset)
        self.skipped_chunks.append((offset, reason))
        log.warning("%s: %s; its messages are skipped", self.path, reason)

    def chunk_span(self, offset: int) -> tuple[int, int] | None:
        """The time range the chunk index gives the chunk at ``offset`` (None if unknown)."""
        starts, ends, offsets = self.chunk_table()
        for i, o in enumerate(offsets):
            if o == offset:
                return starts[i], ends[i]
        return None

    def _decode_chunk_uncached(self, offset: int) -> list[RawMessage]:
        return self._chunks.decode(self._data, offset, self.topics)

    def iter_chunk_messages(
        self, start_ns: int | None, end_ns: int | None, *, reverse: bool
    ) -> Iterator[list[RawMessage]]:
        """The messages of every chunk that may hold the range (loose messages first)."""
        chosen = self.offsets_in_range(start_ns, end_ns)
        if self.loose and not reverse:
            yield self.loose
        for offset in reversed(chosen) if reverse else chosen:
            yield self.chunk_messages(offset)
        if self.loose and reverse:
            yield self.loose

    def iter_messages(
        self, start_ns: int | None = None, end_ns: int | None = None, *, reverse: bool = False
    ) -> Iterator[RawMessage]:
        """Raw messages with ``start_ns <= log_time <= end_ns``, in file order per chunk."""
        for messages in self.iter_chunk_messages(start_ns, end_ns, reverse=reverse):
            for msg in reversed(messages) if reverse else messages:
                if (start_ns is None or msg.log_time_ns >= start_ns) and (
                    end_ns is None or msg.log_time_ns <= end_ns
                ):
                    yield msg

    def time_range(self) -> tuple[int, int]:
        """(first, last) log time from the chunks' time ranges and the loose messages, without
        decoding a chunk (0, 0 for a file that holds no message)."""
        starts, ends, _offsets = self.chunk_table()
        times = [*starts, *ends, *(m.log_time_ns for m in self.loose)]
        return min(times, default=0), max(times, default=0)

    def channel_counts(self) -> tuple[int, int, int, dict[str, int]]:
        """(start ns, end ns, chunk count, messages per topic), from the summary or a scan."""
        trusted = self.trusted_statistics()
        if trusted is not None:
            return trusted
        channels: dict[str, int] = {}
        for messages in self.iter_chunk_messages(None, None, reverse=False):
            for msg in messages:
                channels[msg.topic] = channels.get(msg.topic, 0) + 1
        start, end = self.time_range()
        return start, end, len(self.chunk_table()[0]), channels
