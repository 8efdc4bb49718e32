"""Writing one MCAP segment of the TRACE profile, a batch of whole cycles per chunk.

The `mcap` library's Writer keeps its open chunk in memory until it reaches ``chunk_size``,
so a killed process loses that chunk. Here every ``write_batch`` call closes a chunk and
hands it, with its message indexes, to the OS in one write: a batch that returned is on
disk as far as the process is concerned, and a crash can only cut the batch in flight.
A failed write is rolled back (the file is truncated to the end of the last good batch) so
the segment stays valid and the caller can drop the batch and go on. When even the rollback
fails (a full disk: a buffered stream cannot seek without writing first) the file is closed
and its real end, read after the close, says whether the batch's chunk is in it whole: a
reader of the unfinished segment keeps a complete chunk and cuts a partial one
(schemas/PROFILE.md §8), so the caller is told which of the two the file holds.
"""

from __future__ import annotations

import array
import contextlib
import errno
import os
import struct
import sys
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import BinaryIO

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from trace_runtime.encoding.mcap_records import CHUNK_TABLE_ATTACHMENT, MAGIC
from trace_runtime.errors import SegmentWriteError
from trace_runtime.logger.mcap_out import (
    CHUNK_HEADER,
    INDEX_ENTRY,
    INDEX_HEADER,
    OPCODE_CHANNEL,
    OPCODE_CHUNK,
    OPCODE_MESSAGE_INDEX,
    OPCODE_METADATA,
    OPCODE_SCHEMA,
    U64,
    MessageFields,
    builder_bytes,
    encode_record,
    message_records,
)
from trace_runtime.records import LAYER_TOPICS, PROFILE, TOPIC_SEAL
from trace_runtime.schemas import SENSOR_SCHEMA_NAME, schema_bytes, schema_name
from trace_runtime.session import SESSION_METADATA, SessionInfo

LIBRARY = "trace_runtime 0.1"


@dataclass(slots=True)
class _ChannelSpec:
    id: int
    topic: str
    schema_id: int
    encoding: str
    metadata: dict[str, str] = field(default_factory=dict)


class SegmentWriter:
    """Writes an MCAP file: header, schemas, channels, session metadata, chunks, summary.

    ``message_encoding`` and the channel table are per segment; the hot tier uses ``json``.
    """

    def __init__(
        self,
        stream: BinaryIO,
        session: SessionInfo,
        *,
        compression: str = "zstd",
        level: int = 3,
        extra_metadata: Sequence[tuple[str, dict[str, str]]] = (),
    ) -> None:
        self._stream = stream
        self.session = session
        self._compression = compression
        self._compressor = zstandard.ZstdCompressor(level=level) if compression == "zstd" else None
        self._schemas: dict[str, Schema] = {}
        self._channels: dict[str, _ChannelSpec] = {}
        self._pending = b""  # schema/channel records not yet on disk
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._message_counts: dict[int, int] = {}
        self._start_ns: int | None = None
        self._end_ns = 0
        self.offset = 0
        self.broken = False
        self.finished = False
        self.file_end: int | None = None
        """Once ``broken``: the file's size after it was closed (None: it cannot be known,
        the stream has no file descriptor)."""

        head = RecordBuilder()
        head.write(MAGIC)
        Header(profile=PROFILE, library=LIBRARY).write(head)
        self._write_now(builder_bytes(head))
        for topic in (*LAYER_TOPICS, TOPIC_SEAL):
            self.channel(topic)
        self.add_metadata(SESSION_METADATA, session.to_metadata())
        for name, data in extra_metadata:
            self.add_metadata(name, data)

    # --- channels and metadata ---------------------------------------------------------

    def channel(
        self,
        topic: str,
        *,
        encoding: str = "json",
        schema: tuple[str, str, bytes] | None = None,
    ) -> int:
        """Channel id of ``topic``, registering it (and its schema) on first use.

        ``schema`` is (name, encoding, data); by default /trace topics get their generated
        JSON Schema and other topics the permissive sensor schema.
        """
        spec = self._channels.get(topic)
        if spec is not None:
            return spec.id
        if schema is None:
            name = schema_name(topic) if topic.startswith("/trace/") else SENSOR_SCHEMA_NAME
            schema = (name, "jsonschema", schema_bytes(topic))
        name, schema_encoding, data = schema
        record = self._schemas.get(name)
        if record is None:
            record = Schema(
                id=len(self._schemas) + 1, name=name, encoding=schema_encoding, data=data
            )
            self._schemas[name] = record
            self._pending += encode_record(record)
        spec = _ChannelSpec(len(self._channels) + 1, topic, record.id, encoding)
        self._channels[topic] = spec
        self._pending += encode_record(
            Channel(
                id=spec.id,
                topic=topic,
                message_encoding=encoding,
                schema_id=record.id,
                metadata=spec.metadata,
            )
        )
        return spec.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write a metadata record now (outside any chunk) and index it."""
        start = self.offset + len(self._pending)
        record = encode_record(Metadata(name=name, metadata=data))
        self._write_now(record)
        self._metadata_indexes.append(MetadataIndex(offset=start, length=len(record), name=name))

    # --- data --------------------------------------------------------------------------

    def write_batch(self, messages: Sequence[MessageFields]) -> int:
        """Write ``messages`` as one chunk and flush it to the OS; return bytes written.

        On failure the file is truncated back to the last good batch and
        ``SegmentWriteError(rolled_back=True)`` is raised; if even that fails the segment is
        marked broken (``rolled_back=False``), its stream closed, and it must be abandoned;
        the error's ``kept`` then says whether the file ends past the batch's chunk (a reader
        recovers the batch) or before its end (a reader cuts it: the batch is lost).
        """
        if self.broken or self.finished:
            raise SegmentWriteError("segment is closed", rolled_back=False)
        if not messages:
            return 0
        records, indexes, start, end = message_records(messages)
        payload = self._compressor.compress(records) if self._compressor else bytes(records)

        before = self.offset
        chunk_offset = self.offset + len(self._pending)  # where this batch's chunk will start
        out, chunk_length, offsets = self._chunk(records, payload, indexes, start, end)
        index_length = len(out) - chunk_length
        try:
            self._write_now(bytes(out))
        except SegmentWriteError as err:
            file_end = self.file_end
            if err.rolled_back or file_end is None or file_end < chunk_offset + chunk_length:
                raise
            raise SegmentWriteError(
                f"{err}; the batch is in the file",
                rolled_back=False,
                kept=True,
                written=file_end - before,
            ) from err

        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_offset,
                chunk_length=chunk_length,
                message_index_offsets=offsets,
                message_index_length=index_length,
                compression=self._compression,
                compressed_size=len(payload),
                uncompressed_size=len(records),
            )
        )
        counts = self._message_counts
        for channel_id, entries in indexes.items():
            counts[channel_id] = counts.get(channel_id, 0) + len(entries) // INDEX_ENTRY.size
        self._start_ns = start if self._start_ns is None else min(self._start_ns, start)
        self._end_ns = max(self._end_ns, end)
        return self.offset - before

    def _chunk(
        self,
        records: bytearray,
        payload: bytes,
        indexes: dict[int, bytearray],
        start: int,
        end: int,
    ) -> tuple[bytearray, int, dict[int, int]]:
        """The chunk record of one batch followed by its message indexes, the chunk's length,
        and where each channel's message index will sit in the file."""
        chunk_offset = self.offset + len(self._pending)  # where this batch's chunk will start
        compression = self._compression.encode()
        body_len = 8 + 8 + 8 + 4 + 4 + len(compression) + 8 + len(payload)
        out = bytearray(
            CHUNK_HEADER.pack(
                OPCODE_CHUNK,
                body_len,
                start,
                end,
                len(records),
                zlib.crc32(records),
                len(compression),
            )
        )
        out += compression
        out += U64.pack(len(payload))
        out += payload
        chunk_length = len(out)
        offsets: dict[int, int] = {}
        for channel_id, entries in indexes.items():
            offsets[channel_id] = chunk_offset + len(out)
            out += INDEX_HEADER.pack(
                OPCODE_MESSAGE_INDEX, 2 + 4 + len(entries), channel_id, len(entries)
            )
            out += entries
        return out, chunk_length, offsets

    def sync(self) -> None:
        """fsync the file, when the stream has a file descriptor."""
        fileno = self._fileno()
        if fileno is not None:
            os.fsync(fileno)

    def storage_lost(self) -> bool:
        """True when the file was unlinked under the writer (its directory deleted, or the
        file itself): everything written to it is gone once it is closed.

        One ``fstat`` (about a microsecond); False for streams without a file descriptor,
        which cannot be checked.
        """
        fileno = self._fileno()
        if fileno is None:
            return False
        try:
            return os.fstat(fileno).st_nlink == 0
        except OSError:
            return False  # the next write reports what is wrong with the descriptor

    def _fileno(self) -> int | None:
        try:
            return self._stream.fileno()
        except (AttributeError, OSError, ValueError):
            return None

    def finish(self) -> None:
        """Write the data end, the summary (schemas, channels, statistics, indexes), the footer."""
        if self.finished or self.broken:
            return
        out = RecordBuilder()
        attachment_index = self._chunk_table(out)
        DataEnd(data_section_crc=0).write(out)
        summary_start = self.offset + len(self._pending) + out.count
        summary_bytes, groups = self._summary(summary_start, attachment_index)
        offsets = RecordBuilder()
        for opcode, begin, length in groups:
            SummaryOffset(group_opcode=opcode, group_start=begin, group_length=length).write(
                offsets
            )
        offset_bytes = builder_bytes(offsets)
        summary_offset_start = summary_start + len(summary_bytes)
        footer_prefix = struct.pack("<BQQQ", 0x02, 20, summary_start, summary_offset_start)
        crc = zlib.crc32(summary_bytes + offset_bytes + footer_prefix)
        tail = RecordBuilder()
        Footer(
            summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc
        ).write(tail)
        self._write_now(
            builder_bytes(out) + summary_bytes + offset_bytes + builder_bytes(tail) + MAGIC
        )
        self.finished = True
        self.sync()

    def _chunk_table(self, out: RecordBuilder) -> AttachmentIndex | None:
        """Write the chunk table attachment (every chunk's first and last time and offset, in
        columns, for a reader's seek) into ``out`` when the chunks are in time order, and
        return its index entry; None when they are not."""
        starts = array.array("Q", [c.message_start_time for c in self._chunk_indexes])
        ends = array.array("Q", [c.message_end_time for c in self._chunk_indexes])
        attachment_index: AttachmentIndex | None = None
        if list(starts) == sorted(starts) and list(ends) == sorted(ends):
            places = array.array("Q", [c.chunk_start_offset for c in self._chunk_indexes])
            table = starts.tobytes() + ends.tobytes() + places.tobytes()
            if sys.byteorder == "big":
                swapped = array.array("Q", table)
                swapped.byteswap()
                table = swapped.tobytes()
            attachment_offset = self.offset + len(self._pending)
            Attachment(
                log_time=self._start_ns or 0,
                create_time=self._start_ns or 0,
                name=CHUNK_TABLE_ATTACHMENT,
                media_type="application/x-trace-chunk-columns",
                data=table,
            ).write(out)
            attachment_index = AttachmentIndex(
                offset=attachment_offset,
                length=out.count,
                log_time=self._start_ns or 0,
                create_time=self._start_ns or 0,
                data_size=len(table),
                name=CHUNK_TABLE_ATTACHMENT,
                media_type="application/x-trace-chunk-columns",
            )
        return attachment_index

    def _summary(
        self, summary_start: int, attachment_index: AttachmentIndex | None
    ) -> tuple[bytes, list[tuple[int, int, int]]]:
        """The summary section (schemas, channels, statistics, chunk, attachment and metadata
        indexes) starting at ``summary_start``, and its groups (opcode, start, length)."""
        summary = RecordBuilder()
        groups: list[tuple[int, int, int]] = []

        def group(opcode: int, records: Sequence[object]) -> None:
            if not records:
                return
            begin = summary.count
            for record in records:
                record.write(summary)  # type: ignore[attr-defined]
            groups.append((opcode, summary_start + begin, summary.count - begin))

        group(OPCODE_SCHEMA, list(self._schemas.values()))
        group(
            OPCODE_CHANNEL,
            [
                Channel(
                    id=c.id,
                    topic=c.topic,
                    message_encoding=c.encoding,
                    schema_id=c.schema_id,
                    metadata=c.metadata,
                )
                for c in self._channels.values()
            ],
        )
        group(
            0x0B,
            [
                Statistics(
                    message_count=sum(self._message_counts.values()),
                    schema_count=len(self._schemas),
                    channel_count=len(self._channels),
                    attachment_count=0 if attachment_index is None else 1,
                    metadata_count=len(self._metadata_indexes),
                    chunk_count=len(self._chunk_indexes),
                    message_start_time=self._start_ns or 0,
                    message_end_time=self._end_ns,
                    channel_message_counts=dict(self._message_counts),
                )
            ],
        )
        group(0x08, self._chunk_indexes)
        group(0x0A, [] if attachment_index is None else [attachment_index])
        group(OPCODE_METADATA + 1, self._metadata_indexes)
        return builder_bytes(summary), groups

    def close(self) -> None:
        """Finish (if still healthy) and close the underlying stream."""
        try:
            self.finish()
        finally:
            self._stream.close()

    # --- io ----------------------------------------------------------------------------

    def _write_now(self, data: bytes) -> None:
        """Write ``data`` after any pending schema/channel records, all or nothing."""
        good = self.offset
        data = self._pending + data
        try:
            written = self._stream.write(data)
            if written is not None and written < len(data):
                self._write_rest(data, written)
            self._stream.flush()
        except (OSError, ValueError) as err:
            self._roll_back(good, err)
        self._pending = b""
        self.offset = good + len(data)

    def _write_rest(self, data: bytes, done: int) -> None:
        """An unbuffered stream took only part of ``data`` (a filling disk shows so, and
        raises ENOSPC only at the next write): write the rest, or raise."""
        while done < len(data):
            written = self._stream.write(data[done:])
            if not written:
                raise OSError(errno.EIO, f"short write: {done} of {len(data)} bytes")
            done += written

    def _roll_back(self, good: int, err: Exception) -> None:
        try:
            self._stream.seek(good)
            self._stream.truncate(good)
            self._stream.flush()
        except (OSError, ValueError):
            self._give_up()
            raise SegmentWriteError(
                f"write failed ({err}); rollback failed", rolled_back=False
            ) from err
        raise SegmentWriteError(f"write failed ({err})", rolled_back=True) from err

    def _give_up(self) -> None:
        """A write could not be rolled back: close the stream and read where the file ends.

        The end is read after the close, through a copy of the descriptor, because closing
        a buffered stream writes what it still held: only then is the file's end final.
        """
        self.broken = True
        fileno = self._fileno()
        copy: int | None = None
        if fileno is not None:
            with contextlib.suppress(OSError):  # no descriptor left: the end stays unknown
                copy = os.dup(fileno)
        with contextlib.suppress(OSError, ValueError):  # already failing; the end tells
            self._stream.close()
        if copy is None:
            return
        try:
            self.file_end = os.fstat(copy).st_size
        except OSError:
            self.file_end = None
        finally:
            os.close(copy)
