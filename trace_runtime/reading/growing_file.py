"""A hot segment read while its logger writes it: each poll decodes only what was appended.

``reader.Segment`` opens a file as it is at that moment; a segment without a footer is then
found by a walk of its whole data section, every chunk decoded. A follower that re-opened a
growing segment at every poll would pay for the whole segment each time, more the longer the
robot runs. ``GrowingSegment`` remembers where the last complete record it read ends and, at
the next poll, reads from there: the records appended since, up to the last complete one. A
record cut short at the end (a chunk the writer is still handing to the OS) is not read: the
next poll starts at it again. What it keeps between polls is bounded: the file offset, the
channel table, the session, and the messages of a cycle whose seal is not written yet.

It reads the hot tier only (a warm or cold segment is written whole, aside, and then
finished: ``reader.Segment`` reads those), with the byte layer's own framing and chunk
decoding (``mcap_records``, ``mcap_chunks``) and the hot tier's assembly (``cycles``), so a
cycle read here is the cycle ``Segment`` reads. A damaged chunk is stepped over as the reader
steps over one (the cycle it cut is lost with it); a limit hit is raised.
"""

from __future__ import annotations

import contextlib
import logging
import os
import struct
from collections.abc import Iterator
from pathlib import Path

from trace_runtime.encoding.cycles import Cycle, RawMessage, assemble_hot, raw_message
from trace_runtime.encoding.mcap_chunks import ChunkDecoder
from trace_runtime.encoding.mcap_records import (
    DAMAGE,
    FOOTER_SIZE,
    MAGIC,
    MESSAGE_FIXED,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_METADATA,
    RECORD_HEADER,
    damage_reason,
    read_str,
)
from trace_runtime.errors import LogLimitError, LogReadError, NotHotSegmentError, NotTraceLogError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import PROFILE, TOPIC_SEAL
from trace_runtime.session import SESSION_METADATA, SessionInfo

__all__ = ["GrowingSegment", "NotHotSegmentError"]

log = logging.getLogger("trace_runtime")

_READ_BLOCK = 1 << 20
"""How much is read from the file at a time: a poll reads what was appended in pieces of
this size (plus at most one record), never the whole file at once."""


class GrowingSegment:
    """One hot segment followed as it grows (``poll``), from its first byte or, after a
    first poll, from where the last complete record read ends."""

    def __init__(self, path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        self.path = Path(path)
        self.limits = limits
        self.offset = 0
        """Where the next record to read starts (0: the header is not read yet)."""
        self.session: SessionInfo | None = None
        """The segment's ``trace.session`` record, once read (the first poll that reaches it)."""
        self.start_ns: int | None = None
        """The earliest time of the chunks read so far (the segment's start, as
        ``Segment.start_ns`` gives it for a file without a summary)."""
        self.data_ended = False
        """The writer closed the data section (a Data End record): nothing more is appended
        to it; ``finished`` once the footer is there too."""
        self.finished = False
        self.skipped_chunks = 0
        """Damaged chunks stepped over (each logged once, as the reader does)."""
        self.bytes_read = 0
        """Bytes read from the file over all polls (what following it cost)."""
        self._size = -1
        self._topics: dict[int, str] = {}
        self._open: list[RawMessage] = []
        self._open_bytes = 0
        self._chunks = ChunkDecoder(self.path, limits)

    def poll(self) -> Iterator[Cycle]:
        """The cycles the records appended since the last poll close (sealed ones; the
        messages after the last seal wait for theirs), oldest first, a chunk at a time.

        Raises ``LogReadError`` when the file is gone, shrank under what was read or is not
        a TRACE hot segment, and ``LogLimitError`` when a record breaks the reader's limits."""
        try:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
        except OSError as err:
            raise LogReadError(str(self.path), f"cannot read ({err.strerror or err})") from err
        try:
            size = os.fstat(fd).st_size
            if size == self._size:
                return
            if size < self.offset:
                raise LogReadError(str(self.path), f"shrank to {size} bytes under its reader")
            if not self.data_ended:
                for messages in self._read(fd, size):
                    yield from self._cycles(messages)
            if self.data_ended:
                self.finished = self.finished or _ends_in_footer(fd, size)
            self._size = size  # all of it read: the next poll looks only if it grows
        finally:
            os.close(fd)

    def has_footer(self) -> bool:
        """Whether the file ends in a footer right now (its logger closed it), looked at
        without reading what is before it."""
        try:
            fd = os.open(self.path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
        except OSError:
            return False
        try:
            return _ends_in_footer(fd, os.fstat(fd).st_size)
        finally:
            os.close(fd)

    # --- records -------------------------------------------------------------------------

    def _read(self, fd: int, size: int) -> Iterator[list[RawMessage]]:
        """The messages of each complete record between ``offset`` and ``size`` that holds
        any (a chunk, or a message written outside chunks); ``offset`` moves past each
        record as it is read."""
        if self.offset == 0 and not self._read_header(fd, size):
            return
        block = _Block(self.path, fd, size)
        pos = self.offset
        while pos + 9 <= size:
            opcode, length = RECORD_HEADER.unpack_from(block.at(pos, 9))
            if length > self.limits.max_record_bytes:
                raise LogLimitError(
                    str(self.path), f"record at offset {pos} of {length} bytes is over the limit"
                )
            end = pos + 9 + length
            if end > size:
                return  # cut short: still being written, read again at the next poll
            found: list[RawMessage] = []
            if opcode == OP_CHUNK:
                found = self._chunk(block.at(pos, 9 + length), pos)
            elif opcode == OP_CHANNEL:
                body = block.at(pos + 9, length)
                with self._as_read_error():
                    channel_id, _schema = struct.unpack_from("<HH", body)
                    self._topics[channel_id] = read_str(body, 4)[0]
            elif opcode == OP_METADATA:
                self._metadata(block.at(pos + 9, length))
            elif opcode == OP_MESSAGE:
                body = block.at(pos + 9, length)
                with self._as_read_error():
                    channel_id, sequence, log_time, _publish = MESSAGE_FIXED.unpack_from(body)
                topic = self._topics.get(channel_id, f"<channel {channel_id}>")
                found = [raw_message(topic, sequence, log_time, bytes(body[22:]))]
            elif opcode in (OP_DATA_END, OP_FOOTER):
                self.data_ended = True
            # schemas, message indexes, attachments: nothing a follower reads
            self.bytes_read += end - pos
            self.offset = pos = end
            if found:
                yield found
            if self.data_ended:
                return

    def _read_header(self, fd: int, size: int) -> bool:
        """Check the magic and the profile; False while the header is not all written."""
        head = os.pread(fd, min(size, 8 + 9), 0)
        if len(head) >= 8 and head[:8] != MAGIC:
            raise LogReadError(str(self.path), "not an MCAP file (bad magic)")
        if len(head) < 17:
            return False
        opcode, length = RECORD_HEADER.unpack_from(head, 8)
        if opcode != OP_HEADER:
            raise LogReadError(str(self.path), "no MCAP header record after the magic")
        if 17 + length > size:
            return False
        if length > self.limits.max_record_bytes:
            raise LogLimitError(str(self.path), "MCAP header record over the limit")
        body = os.pread(fd, length, 17)
        with self._as_read_error():
            profile, _ = read_str(body, 0)
        if profile != PROFILE:
            label = repr(profile) if profile else "none"
            raise NotTraceLogError(str(self.path), f"MCAP profile is {label}, not a TRACE log")
        self.offset = 17 + length
        self.bytes_read += self.offset
        return True

    def _metadata(self, body: bytes) -> None:
        with self._as_read_error():
            name, pos = read_str(body, 0)
            if name != SESSION_METADATA:
                return
            (map_len,) = struct.unpack_from("<I", body, pos)
            pos += 4
            stop = pos + map_len
            values: dict[str, str] = {}
            while pos < stop:
                key, pos = read_str(body, pos)
                values[key], pos = read_str(body, pos)
        try:
            session = SessionInfo.from_metadata(values)
        except ValueError as err:
            raise LogReadError(str(self.path), f"bad trace.session metadata: {err}") from err
        if self.session is not None and session != self.session:
            raise LogReadError(str(self.path), "holds two different trace.session records")
        if session.tier != "hot":
            raise NotHotSegmentError(
                str(self.path), f"a {session.tier} segment is read whole, not followed"
            )
        self.session = session

    def _chunk(self, record: bytes, offset: int) -> list[RawMessage]:
        """The messages of one complete chunk record; none from a damaged one, which is
        skipped with the cycle it cut (as ``reader.Segment`` skips one)."""
        try:
            start_ns = struct.unpack_from("<Q", record, 9)[0]
            decoded = self._chunks.decode(record, 0, self._topics)
        except LogLimitError as err:
            raise LogLimitError(str(self.path), f"at offset {offset}: {err.reason}") from err
        except LogReadError as err:
            self._skip(offset, err.reason)
            return []
        except DAMAGE as err:
            self._skip(offset, damage_reason(err))
            return []
        if self.start_ns is None or start_ns < self.start_ns:
            self.start_ns = start_ns
        return decoded

    def _skip(self, offset: int, reason: str) -> None:
        self.skipped_chunks += 1
        log.warning("%s: chunk at offset %d skipped (%s)", self.path, offset, reason)
        self._open, self._open_bytes = [], 0

    def _as_read_error(self) -> contextlib.AbstractContextManager[None]:
        return _damage_as_read_error(self.path)

    # --- cycles --------------------------------------------------------------------------

    def _cycles(self, messages: list[RawMessage]) -> list[Cycle]:
        """The cycles closed by a seal among the open messages and ``messages``; what follows
        the last seal stays open for the next poll (bounded: a run past the chunk limit
        without a seal is damage, and is dropped)."""
        if not messages:
            return []
        last = -1
        for i in range(len(messages) - 1, -1, -1):
            if messages[i].topic == TOPIC_SEAL:
                last = i
                break
        run = self._open + messages[: last + 1] if last >= 0 else []
        rest = messages[last + 1 :] if last >= 0 else self._open + messages
        self._open = rest
        self._open_bytes = sum(len(m.data) for m in rest)
        if self._open_bytes > self.limits.max_chunk_bytes:
            log.warning("%s: %d bytes without a seal dropped", self.path, self._open_bytes)
            self._open, self._open_bytes = [], 0
        return assemble_hot(run, self.path.name) if run else []


class _Block:
    """Reads of one file up to ``end``, ``_READ_BLOCK`` at a time: a poll's many small
    records cost one system call a block, not one a record."""

    def __init__(self, path: Path, fd: int, end: int) -> None:
        self._path, self._fd, self._end = path, fd, end
        self._start, self._data = 0, b""

    def at(self, pos: int, length: int) -> bytes:
        start, data = self._start, self._data
        if start <= pos and pos + length <= start + len(data):
            return data[pos - start : pos - start + length]
        data = os.pread(self._fd, min(max(length, _READ_BLOCK), self._end - pos), pos)
        if len(data) < length:
            raise LogReadError(str(self._path), f"shrank while read (at offset {pos})")
        self._start, self._data = pos, data
        return data[:length]


@contextlib.contextmanager
def _damage_as_read_error(path: Path) -> Iterator[None]:
    """What parsing a damaged record raises, as one ``LogReadError`` naming the file."""
    try:
        yield
    except DAMAGE as err:
        raise LogReadError(str(path), damage_reason(err)) from err


def _ends_in_footer(fd: int, size: int) -> bool:
    """Whether the file ends in a footer and the closing magic (its writer closed it)."""
    if size < 8 + FOOTER_SIZE + 8:
        return False
    tail = os.pread(fd, FOOTER_SIZE + 8, size - FOOTER_SIZE - 8)
    if tail[-8:] != MAGIC:
        return False
    opcode, length = RECORD_HEADER.unpack_from(tail, 0)
    return bool(opcode == OP_FOOTER and length == 20)
