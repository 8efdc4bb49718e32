"""The MCAP level of ``doctor``: header, schemas, channels, session metadata, chunks, summary.

It walks one file record by record with the reference ``mcap`` library (not with our own
reader: a conformance checker should not share the bugs of the reader whose input it judges),
bounded as our reader is: a record may not claim more than the file holds, a chunk may not
inflate past ``ReadLimits``. Each message it meets goes to the content checker
(``content.CycleCheck``) with its channel and the file offset of its chunk.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import zstandard
from mcap.exceptions import McapError
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import StreamReader, breakup_chunk

from trace_audit.doctor.content import CycleCheck
from trace_audit.doctor.rules import SegmentDoctor
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_records import (
    OP_CHANNEL,
    OP_CHUNK_INDEX,
    OP_METADATA_INDEX,
    OP_SCHEMA,
    OP_STATISTICS,
)
from trace_runtime.errors import LogLimitError, LogReadError, TraceError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import MESSAGE_MODELS, PROFILE
from trace_runtime.schemas import schema_name
from trace_runtime.session import SESSION_METADATA, SessionInfo
from trace_runtime.tier_formats.cold import BLOCK_TOPIC, INDEX_TOPIC, BlockCache, iter_decoded
from trace_runtime.tier_formats.warm import SUMMARY_TOPIC

__all__ = ["check_structure"]

_MAGIC = b"\x89MCAP0\r\n"
_SESSION_KEYS = (
    "robot_id",
    "period_ns",
    "software_version",
    "policy_version",
    "clock",
    "segment",
    "prev_seal",
    "first_cycle",
    "tier",
    "profile_version",
)
_TIER_TOPICS = {"warm": (SUMMARY_TOPIC,), "cold": (BLOCK_TOPIC, INDEX_TOPIC)}
"""Channels of the compacted tiers (PROFILE section 9), which section 3 does not list."""
_DAMAGE = (McapError, struct.error, EOFError, ValueError, KeyError, UnicodeDecodeError)
"""What the mcap library raises on a damaged or cut record."""
_CHUNK_DAMAGE = (*_DAMAGE, zstandard.ZstdError, RuntimeError)
"""And on a chunk whose compressed bytes are damaged: its decompressors raise their own
errors (zstd's ``ZstdError``, lz4's ``RuntimeError``) before any CRC is compared."""


@dataclass(slots=True)
class _Seen:
    """What the walk found, for the checks that need the whole file, and where it reports."""

    report: SegmentDoctor
    content: CycleCheck
    limits: ReadLimits
    progress: Callable[[int], None] | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    channel_at: dict[int, int] = field(default_factory=dict)  # where each was first seen
    chunks: dict[int, Chunk] = field(default_factory=dict)  # by file offset
    metadata_at: dict[int, str] = field(default_factory=dict)
    sessions: int = 0
    session: SessionInfo | None = None
    messages_per_channel: dict[int, int] = field(default_factory=dict)
    start_ns: int | None = None
    end_ns: int | None = None
    summary: list[Any] = field(default_factory=list)
    footer: Footer | None = None
    data_end: bool = False
    last_chunk_start: int | None = None
    cold_pending: list[RawMessage] = field(default_factory=list)  # up to the next block
    cold_cache: BlockCache = field(default_factory=lambda: BlockCache(0))


def check_structure(
    path: Path,
    report: SegmentDoctor,
    limits: ReadLimits = DEFAULT_LIMITS,
    progress: Callable[[int], None] | None = None,
) -> SessionInfo | None:
    """Check one segment file's MCAP records and every message in it; return its session.
    ``progress(offset)`` is called after each chunk with the bytes of the file read so far.

    Raises ``LogReadError`` when the file is not MCAP at all (exit 3); everything after the
    magic and the header is a problem in ``report``, not an exception.
    """
    try:
        stream = path.open("rb")
    except OSError as err:
        raise LogReadError(str(path), err.strerror or str(err)) from err
    with stream:
        if stream.read(8) != _MAGIC:
            raise LogReadError(str(path), "not an MCAP file (bad magic)")
        stream.seek(0)
        size = path.stat().st_size
        seen = _Seen(report, CycleCheck(report), limits, progress)
        _walk(stream, size, seen)
        _decode_cold(seen, None)
        stream.seek(max(0, size - 8))
        if seen.footer is not None and stream.read(8) != _MAGIC:
            # A footer without the closing magic: the last write was cut (readers scan it)
            report.add("closed", "the file ends in its footer without the closing magic")
            seen.footer = None
        seen.content.finish(closed=seen.footer is not None)
    report.closed = seen.footer is not None and seen.footer.summary_start != 0
    for channel_id, channel in seen.channels.items():
        _check_channel(channel, seen, report, seen.channel_at[channel_id])
    _check_session(seen, report)
    _check_summary(seen, report)
    return seen.session


def _records(stream: IO[bytes], size: int) -> Iterator[tuple[int, Any]]:
    """(file offset, record) in file order; stops at a record cut short (a crash)."""
    reader = StreamReader(stream, emit_chunks=True, record_size_limit=size)
    start = 8
    for record in reader.records:
        yield start, record
        start = stream.tell()
        if isinstance(record, Footer):
            return


def _walk(stream: IO[bytes], size: int, seen: _Seen) -> None:
    report = seen.report
    offset = 8
    try:
        for offset, record in _records(stream, size):
            if seen.data_end:
                seen.summary.append((offset, record))
                if isinstance(record, Footer):
                    seen.footer = record
                continue
            _data_record(offset, record, seen)
    except LogLimitError:
        raise
    except _DAMAGE as err:
        if offset == 8 and not isinstance(err, EOFError):
            raise LogReadError(str(report.path), f"no readable MCAP header ({err})") from err
        if _ends_after_record(stream, offset, size):
            text = (
                f"the file ends after the complete record at offset {offset}, without a "
                "footer (its writer stopped between records, or is still writing it: not "
                "closed; readers scan it and keep every record)"
            )
        else:
            text = (
                f"the file ends in a record cut short after offset {offset} (not closed: "
                "readers scan it and keep every complete record)"
            )
        report.add("closed", text, offset=offset)


def _ends_after_record(stream: IO[bytes], offset: int, size: int) -> bool:
    """Whether the record at ``offset`` is complete and nothing follows it."""
    stream.seek(offset)
    head = stream.read(9)
    if len(head) < 9:
        return False
    (length,) = struct.unpack_from("<Q", head, 1)
    return bool(offset + 9 + length == size)


def _data_record(offset: int, record: Any, seen: _Seen) -> None:
    report = seen.report
    if isinstance(record, Header):
        if record.profile != PROFILE:
            report.add("header-profile", f"profile is {record.profile!r}", offset=offset)
    elif isinstance(record, Schema):
        seen.schemas[record.id] = record
    elif isinstance(record, Channel):
        seen.channels[record.id] = record
        seen.channel_at.setdefault(record.id, offset)
    elif isinstance(record, Metadata):
        seen.metadata_at[offset] = record.name
        if record.name == SESSION_METADATA:
            _session_record(record, seen, report, offset)
    elif isinstance(record, Chunk):
        _chunk(offset, record, seen)
    elif isinstance(record, Message):
        _message(record, offset, seen, in_chunk=False)
    elif isinstance(record, DataEnd):
        seen.data_end = True


def _session_record(record: Metadata, seen: _Seen, report: SegmentDoctor, offset: int) -> None:
    seen.sessions += 1
    if seen.chunks:
        report.add("session", "trace.session comes after the first chunk", offset=offset)
    try:
        seen.session = SessionInfo.from_metadata(dict(record.metadata))
        seen.content.seals_cover_sensors = _version(seen.session.profile_version) >= (1, 3)
    except ValueError as err:
        report.add("session-values", f"trace.session: {err}", offset=offset)
    declared = record.metadata.get("recordings")
    if declared is not None and seen.session is not None:
        _check_recordings(declared, seen.session, report, offset)
    missing = [k for k in _SESSION_KEYS if k not in record.metadata]
    if missing:
        report.add(
            "session-keys",
            f"trace.session lacks {', '.join(missing)} (readers assume the defaults)",
            offset=offset,
        )


def _check_recordings(text: str, session: SessionInfo, report: SegmentDoctor, offset: int) -> None:
    """Profile 1.4: ``recordings`` is a JSON object of recording names to paths; readers keep
    only the well-formed entries, so one they drop is a recording nobody will find."""
    try:
        value = json.loads(text)
    except ValueError:
        value = None
    if not isinstance(value, dict) or len(value) != len(session.recordings):
        report.add(
            "session-values",
            "trace.session recordings is not a JSON object of recording names (a folder's "
            "or file's name) to paths: readers drop what is not",
            offset=offset,
        )


def _version(text: str) -> tuple[int, ...]:
    """A ``major.minor`` profile version as numbers; (0,) when it is not one."""
    try:
        return tuple(int(part) for part in text.split("."))
    except ValueError:
        return (0,)


def _tier(seen: _Seen) -> str:
    return seen.session.tier if seen.session is not None else "hot"


def _check_channel(channel: Channel, seen: _Seen, report: SegmentDoctor, offset: int) -> None:
    """Section 3 for one channel, in its segment's tier (section 9: a compacted tier has
    its own channels and, in cold, its own message encoding; docs/storage.md)."""
    topic = channel.topic
    tier = _tier(seen)
    if topic in _TIER_TOPICS.get(tier, ()):
        return
    if tier == "cold":
        return  # every message of a cold segment lives in its blocks
    if topic.startswith("/trace/"):
        if topic not in MESSAGE_MODELS:
            report.add("known-channel", f"unknown channel {topic}", offset=offset)
            return
        schema = seen.schemas.get(channel.schema_id)
        want = schema_name(topic)
        if schema is None or schema.name != want or schema.encoding != "jsonschema":
            got = (
                f"schema {schema.name!r} in encoding {schema.encoding!r}" if schema else "no schema"
            )
            report.add(
                "channel-schema",
                f"{topic} has {got}, not {want!r} in 'jsonschema'",
                offset=offset,
            )
        if channel.message_encoding != "json":
            report.add(
                "message-encoding",
                f"{topic} uses message encoding {channel.message_encoding!r}",
                offset=offset,
            )
    elif channel.message_encoding != "json":
        report.add(
            "sensor-encoding",
            f"{topic} uses message encoding {channel.message_encoding!r}",
            offset=offset,
        )


def _chunk(offset: int, chunk: Chunk, seen: _Seen) -> None:
    report, limits = seen.report, seen.limits
    if seen.progress is not None:
        seen.progress(offset)
    seen.chunks[offset] = chunk
    report.chunks += 1
    # (a cold segment's blocks are zstd-compressed inside; its chunks need not be)
    if chunk.compression != "zstd" and _tier(seen) != "cold":
        report.add("chunk-compression", f"a chunk is {chunk.compression or 'uncompressed'}")
    if seen.last_chunk_start is not None and chunk.message_start_time < seen.last_chunk_start:
        report.add(
            "chunk-order",
            "a chunk starts earlier than the chunk before it",
            offset=offset,
        )
    seen.last_chunk_start = chunk.message_start_time
    if chunk.uncompressed_size > limits.chunk_bytes(len(chunk.data)):
        raise LogLimitError(
            report.path, f"chunk at offset {offset} declares {chunk.uncompressed_size} bytes"
        )
    try:
        records = breakup_chunk(chunk, validate_crc=True)
    except _CHUNK_DAMAGE as err:
        report.add("readable", f"chunk does not decode ({err})", offset=offset)
        seen.content.damage()
        return
    if len(records) > limits.chunk_records(len(chunk.data)):
        raise LogLimitError(report.path, f"chunk at offset {offset} holds too many records")
    for record in records:
        if isinstance(record, Schema):
            seen.schemas[record.id] = record
        elif isinstance(record, Channel):
            seen.channels[record.id] = record
            seen.channel_at.setdefault(record.id, offset)
        elif isinstance(record, Message):
            _message(record, offset, seen)


def _message(message: Message, offset: int, seen: _Seen, *, in_chunk: bool = True) -> None:
    channel = seen.channels.get(message.channel_id)
    topic = channel.topic if channel else f"<channel {message.channel_id}>"
    counts = seen.messages_per_channel
    counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
    t = message.log_time
    # comparisons, not min()/max() calls: this runs for every message of the log
    if seen.start_ns is None or t < seen.start_ns:
        seen.start_ns = t
    if seen.end_ns is None or t > seen.end_ns:
        seen.end_ns = t
    if seen.session is not None and seen.session.tier == "cold":
        seen.cold_pending.append(RawMessage(topic, message.sequence, t, message.data))
        if topic == BLOCK_TOPIC:
            _decode_cold(seen, offset)
        return
    seen.content.message(topic, message, offset, in_chunk=in_chunk)


def _decode_cold(seen: _Seen, offset: int | None) -> None:
    """Cold blocks are a columnar re-encoding (docs/storage.md) of the original messages:
    each block is decoded back to them, and they get the content checks of a hot segment's.
    A block that does not decode breaks ``readable``. ``offset``: the block's chunk (None at
    the end of the file, for plain messages no block followed)."""
    pending, seen.cold_pending = seen.cold_pending, []
    if not pending:
        return
    try:
        decoded = list(iter_decoded(pending, seen.cold_cache))
    except (TraceError, ValueError) as err:
        where = "" if offset is None else f" in the chunk at offset {offset}"
        seen.report.add("readable", f"a cold block{where} does not decode: {err}", offset=offset)
        seen.content.damage()
        return
    for raw in decoded:
        inner = Message(
            channel_id=0,
            sequence=raw.sequence,
            log_time=raw.log_time_ns,
            publish_time=raw.log_time_ns,
            data=raw.data,
        )
        seen.content.message(raw.topic, inner, offset or 0)


def _check_session(seen: _Seen, report: SegmentDoctor) -> None:
    if seen.sessions == 0:
        report.add("session", "no trace.session metadata record")
    elif seen.sessions > 1:
        report.add("session", f"{seen.sessions} trace.session records (one segment holds one)")


def _check_summary(seen: _Seen, report: SegmentDoctor) -> None:
    """A closed segment's summary: present, complete, and true to the data."""
    if seen.footer is None:
        if not any(p.rule == "closed" for p in report.problems):
            report.add("closed", "no footer: the segment was not closed (readers scan it)")
        return
    if seen.footer.summary_start == 0:
        report.add("summary", "the footer says the file has no summary section")
        return
    kinds = {type(r).__name__ for _, r in seen.summary}
    wanted = ["Schema", "Channel", "Statistics", "SummaryOffset"]
    if seen.chunks:
        wanted.append("ChunkIndex")
    if seen.metadata_at:
        wanted.append("MetadataIndex")
    lacking = [k for k in wanted if k not in kinds]
    if lacking:
        report.add("summary", f"the summary lacks {', '.join(lacking)} records")
    for offset, record in seen.summary:
        _summary_record(offset, record, seen, report)
    indexed = {r.chunk_start_offset for _, r in seen.summary if isinstance(r, ChunkIndex)}
    unindexed = [offset for offset in seen.chunks if offset not in indexed]
    if "ChunkIndex" in kinds and unindexed:
        report.add(
            "summary-agrees",
            f"{len(unindexed)} chunk(s) have no Chunk Index record (a reader that seeks by the "
            "index never reads them)",
            offset=unindexed[0],
        )
    grouped = {r.group_opcode for _, r in seen.summary if isinstance(r, SummaryOffset)}
    present = {
        OP_SCHEMA: "Schema",
        OP_CHANNEL: "Channel",
        OP_STATISTICS: "Statistics",
        OP_CHUNK_INDEX: "ChunkIndex",
        OP_METADATA_INDEX: "MetadataIndex",
    }
    for opcode, name in present.items():
        if name in kinds and opcode not in grouped:
            report.add("summary", f"no Summary Offset record for the {name} group")


def _summary_record(offset: int, record: Any, seen: _Seen, report: SegmentDoctor) -> None:
    if isinstance(record, Statistics):
        counted = sum(seen.messages_per_channel.values())
        if record.message_count != counted:
            report.add(
                "summary-agrees",
                f"Statistics count {record.message_count} messages, the data holds {counted}",
                offset=offset,
            )
        if record.chunk_count != len(seen.chunks):
            report.add(
                "summary-agrees",
                f"Statistics count {record.chunk_count} chunks, the data holds {len(seen.chunks)}",
                offset=offset,
            )
        if counted and (record.message_start_time, record.message_end_time) != (
            seen.start_ns,
            seen.end_ns,
        ):
            report.add(
                "summary-agrees", "Statistics' message time range is not the data's", offset=offset
            )
    elif isinstance(record, ChunkIndex):
        chunk = seen.chunks.get(record.chunk_start_offset)
        if chunk is None:
            report.add(
                "summary-agrees",
                f"a Chunk Index points at offset {record.chunk_start_offset}, where no chunk is",
                offset=offset,
            )
        elif (chunk.message_start_time, chunk.message_end_time) != (
            record.message_start_time,
            record.message_end_time,
        ):
            report.add(
                "summary-agrees",
                f"the Chunk Index of the chunk at {record.chunk_start_offset} gives another "
                "time range than the chunk",
                offset=offset,
            )
    elif isinstance(record, MetadataIndex) and seen.metadata_at.get(record.offset) != record.name:
        report.add(
            "summary-agrees",
            f"a Metadata Index names {record.name!r} at offset {record.offset}, where it is not",
            offset=offset,
        )
