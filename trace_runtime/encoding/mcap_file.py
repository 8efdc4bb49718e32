"""The byte layer of the reader: one MCAP file as records, chunks and messages.

It knows MCAP and nothing of TRACE: the header, the summary (or a linear scan when a crashed
writer left none), metadata records, the chunk table, and decoding a chunk into messages.
Every read is bounded, because an investigator opens files an attacker may have prepared:
``ReadLimits`` caps a chunk's decompressed size (declared and real), the records a chunk may
hold for its compressed size, record lengths and string lengths; a limit hit is a
``LogLimitError`` (a ``LogReadError``), never a ``MemoryError`` or a hang. Beneath it: the
record framing (``mcap_records``), the header, footer and summary records (``mcap_summary``),
the chunk table (``mcap_table``), reading chunks on demand (``mcap_chunk_reader``) and one
chunk's decoding (``mcap_chunks``); the bounds are ``read_limits``.
"""

from __future__ import annotations

import bisect
import contextlib
import logging
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_chunk_reader import ChunkReader
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
    OP_MESSAGE,
    OP_METADATA,
    OP_METADATA_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
    RECORD_HEADER,
    check_fits,
    damage_reason,
    map_file,
    read_str,
)
from trace_runtime.encoding.mcap_summary import (
    Statistics,
    ends_in_footer,
    parse_channel,
    parse_header,
    parse_metadata,
    parse_schema,
    parse_statistics,
    summary_groups,
)
from trace_runtime.encoding.mcap_table import ChunkInfo, ChunkTable, chunk_at, chunk_index_rows
from trace_runtime.errors import LogReadError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits

log = logging.getLogger("trace_runtime")


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
        self._table: ChunkTable | None = None
        self._index_spans: list[tuple[int, int]] = []  # where the Chunk Index records are
        self._attachment_at: int | None = None  # our trace.chunk_columns attachment
        self.statistics: Statistics | None = None
        """(message start ns, message end ns, chunk count, messages per channel id)."""
        self._loose: list[RawMessage] = []
        self.summarized = False
        """Whether the summary section was read (its indexes are hints, checked when used)."""
        self.notes: list[str] = []
        """Indexes of the file that were not used because they disagree with its data."""
        self._chunk_reader = ChunkReader(self.path, limits)
        self.skipped_chunks = self._chunk_reader.skipped
        """Damaged chunks stepped over, by a scan or when read: (file offset, why)."""
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
        if self._parse_header(8) is None:
            raise LogReadError(str(self.path), "truncated before the MCAP header ended")
        return ends_in_footer(self._data)

    def _read_summary(self) -> bool:
        """Read the summary section a footer points at; False when there is none."""
        data = self._data
        footer_at = len(data) - 8 - FOOTER_SIZE
        summary_start, offsets_start, _crc = struct.unpack_from("<QQI", data, footer_at + 9)
        if summary_start == 0:
            return False  # a finished file written without a summary: scan it
        check_fits(summary_start, 0, footer_at)
        ranges = summary_groups(self._data, offsets_start or footer_at, footer_at)
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

    def _parse_summary_records(self, begin: int, end: int) -> None:
        data = self._data
        pos = begin
        while pos + 9 <= end:
            opcode, length = RECORD_HEADER.unpack_from(data, pos)
            body = pos + 9
            check_fits(body, length, end)
            if opcode == OP_SCHEMA:
                schema_id, name = parse_schema(data, body)
                self._schemas[schema_id] = name
            elif opcode == OP_CHANNEL:
                channel_id, topic = parse_channel(data, body)
                self._topic_map[channel_id] = topic
            elif opcode == OP_STATISTICS:
                self.statistics = parse_statistics(data, body)
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

    def _parse_header(self, pos: int) -> int | None:
        header = parse_header(self._data, pos)
        if header is None:
            return None
        self.profile, end = header
        return end

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
                damage = self._chunk_reader.damage(data, pos, self.topics) if decode else None
                if damage is not None:
                    self._chunk_reader.skip(pos, damage)
            elif opcode == OP_SCHEMA:
                schema_id, name = parse_schema(data, body)
                self._schemas[schema_id] = name
            elif opcode == OP_CHANNEL:
                channel_id, topic = parse_channel(data, body)
                self._topic_map[channel_id] = topic
            elif opcode == OP_METADATA and want_metadata:
                self._parse_metadata(body)
            elif opcode in (OP_DATA_END, OP_FOOTER):
                break
            pos = body + length
        if chunks:
            self._table = ChunkTable.from_rows(rows)

    def _parse_metadata_at(self, offset: int) -> None:
        opcode, length = RECORD_HEADER.unpack_from(self._data, offset)
        check_fits(offset + 9, length, len(self._data))
        if opcode == OP_METADATA:
            self._parse_metadata(offset + 9)

    def _parse_metadata(self, body: int) -> None:
        name, values = parse_metadata(self._data, body)
        self._metadata.setdefault(name, []).append(values)

    def _parse_message(self, body: int, length: int, data: bytes) -> RawMessage:
        channel_id, sequence, log_time, _publish = MESSAGE_FIXED.unpack_from(data, body)
        topic = self.topics.get(channel_id, f"<channel {channel_id}>")
        return RawMessage(topic, sequence, log_time, data[body + 22 : body + length])

    # --- the chunk table -------------------------------------------------------------------

    def chunk_table(self) -> tuple[Sequence[int], Sequence[int], Sequence[int]]:
        """(start ns, end ns, file offset) columns of every chunk, sorted by start time."""
        return self._chunk_table().columns()

    def _chunk_table(self) -> ChunkTable:
        if self._table is None:
            with self.damage_as_read_error():
                self._table = self._resolve_table()
        return self._table

    def _resolve_table(self) -> ChunkTable:
        """The chunk table from the first index that agrees with the data: our attachment,
        then the Chunk Index records, then a walk of the data section. Every index is a hint:
        one that disagrees is noted and the next is tried, so no tool that kept a stale copy
        of it, dropped it or never wrote it changes what is read."""
        expected = None if self.statistics is None else self.statistics[2]
        if self._attachment_at is not None:
            table = ChunkTable.from_attachment(self._data, self._attachment_at, expected)
            if isinstance(table, ChunkTable):
                return table
            self._note(f"its {CHUNK_TABLE_ATTACHMENT} attachment is not used: {table}")
        if self._index_spans:
            rows = [
                row for span in self._index_spans for row in chunk_index_rows(self._data, *span)
            ]
            why = self._rows_disagree(rows, expected)
            if why is None and (rows or expected == 0):
                return ChunkTable.from_rows(rows)
            if why is not None:
                self._note(f"its Chunk Index records are not used: {why}")
        elif expected == 0:
            return ChunkTable.from_rows(
                []
            )  # no chunks, says the summary; loose messages were walked
        self._walk_data(chunks=True)
        assert self._table is not None  # the walk sets it
        return self._table

    def _note(self, text: str) -> None:
        self.notes.append(text)
        log.info("%s: %s; the chunks are found another way", self.path, text)

    def _rows_disagree(self, rows: list[tuple[int, int, int]], expected: int | None) -> str | None:
        """Why Chunk Index rows do not describe this file's chunks (None when they do)."""
        if expected is not None and len({r[2] for r in rows}) != expected:
            return f"{len(rows)} of them for the {expected} chunks its Statistics count"
        for start, stop, offset in rows:
            if not chunk_at(self._data, offset, start, stop):
                return f"the one for offset {offset} does not point at a chunk of its times"
        return None

    def chunks(self) -> list[ChunkInfo]:
        """Every chunk's offset and time range, in time order."""
        starts, ends, offsets = self.chunk_table()
        return [ChunkInfo(o, 0, s, e) for s, e, o in zip(starts, ends, offsets, strict=True)]

    def offsets_in_range(self, start_ns: int | None, end_ns: int | None) -> list[int]:
        """File offsets of the chunks that may hold messages in the range, in file order."""
        return self._chunk_table().offsets_in_range(start_ns, end_ns)

    def offsets_back_from(self, t_ns: int) -> Iterator[int]:
        """File offsets of the chunks that start at or before ``t_ns``, the latest first."""
        return self._chunk_table().offsets_back_from(t_ns)

    def previous_offset(self, offset: int) -> int | None:
        """The chunk just before the one at ``offset`` in the file (None for the first)."""
        order = self._file_order()
        i = bisect.bisect_left(order, offset)
        return order[i - 1] if i > 0 else None

    def is_last_chunk(self, offset: int) -> bool:
        order = self._file_order()
        return bool(order) and order[-1] == offset

    def _file_order(self) -> Sequence[int]:
        return self._chunk_table().file_order()

    # --- chunks ----------------------------------------------------------------------------

    def chunk_messages(self, offset: int) -> list[RawMessage]:
        """The messages of the chunk at file ``offset``; the last few decoded are remembered,
        since an investigation asks about neighbouring moments (a seek, then a walk back).

        A chunk that is damaged (fails its CRC, does not decompress, holds broken records)
        gives no messages: it is recorded in ``skipped_chunks``, a warning is logged once,
        and every other chunk is still read. A limit hit is not damage: it is raised.
        """
        return self._chunk_reader.messages(self._data, offset, self.topics)

    def topic_messages(self, topic: str) -> Iterator[RawMessage]:
        """``[m for m in iter_messages() if m.topic == topic]``, one at a time, without
        building the other messages: every chunk is still decoded and checked, and a
        damaged one is skipped and recorded as ``chunk_messages`` does (a pass over a file
        for one rare topic, e.g. its checkpoints, before its cycles are read)."""
        yield from (message for message in self.loose if message.topic == topic)
        offsets = self.offsets_in_range(None, None)
        yield from self._chunk_reader.on_topic(self._data, offsets, self.topics, topic)

    def clear_caches(self) -> None:
        """Forget the recently decoded chunks (to measure a first read)."""
        self._chunk_reader.clear()

    def is_damaged(self, offset: int) -> bool:
        """Whether the chunk at ``offset`` was found damaged (once it has been read)."""
        return offset in self._chunk_reader.damaged

    def chunk_span(self, offset: int) -> tuple[int, int] | None:
        """The time range the chunk index gives the chunk at ``offset`` (None if unknown)."""
        return self._chunk_table().span(offset)

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
