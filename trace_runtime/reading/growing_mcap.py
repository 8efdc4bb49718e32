"""Any MCAP file read while its writer writes it: each poll reads only what was appended.

Opening a growing file anew at every poll costs the whole file each time, more the longer
its writer runs. ``GrowingMcap`` remembers where the last complete record it read ends and,
at the next poll, reads from there: the records appended since, up to the last complete one.
A record cut short at the end (a chunk the writer is still handing to the OS) is not read:
the next poll starts at it again. Between polls it keeps the file offset and the channel
table. A damaged chunk is stepped over (logged once); a limit hit is raised.

It follows a TRACE hot segment (``growing_file.GrowingSegment`` adds the profile check, the
session and the cycles) and a sensor recording another program writes (rosbag2's MCAP files,
followed by the logger so that every message in them is sealed: ``logger.recording_seals``).
"""

from __future__ import annotations

import contextlib
import logging
import os
import struct
from collections.abc import Iterator
from pathlib import Path

from trace_runtime.encoding.cycles import RawMessage, raw_message
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
from trace_runtime.errors import LogLimitError, LogReadError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits

__all__ = ["GrowingMcap"]

log = logging.getLogger("trace_runtime")

_READ_BLOCK = 1 << 20
"""How much is read from the file at a time: a poll reads what was appended in pieces of
this size (plus at most one record), never the whole file at once."""


class GrowingMcap:
    """One MCAP file followed as it grows (``poll_records``), from its first byte or, after a
    first poll, from where the last complete record read ends. Subclasses check the
    header's profile (``_check_profile``) and read metadata records (``_metadata``)."""

    def __init__(self, path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        self.path = Path(path)
        self.limits = limits
        self.offset = 0
        """Where the next record to read starts (0: the header is not read yet)."""
        self.start_ns: int | None = None
        """The earliest time of the chunks read so far."""
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
        self._chunks = ChunkDecoder(self.path, limits)

    def poll_records(self) -> Iterator[list[RawMessage]]:
        """The messages of each complete record appended since the last poll that holds any
        (a chunk, or a message outside chunks), in file order. ``offset`` moves past a record
        before its messages are handed out, so a caller may stop between records and the next
        poll goes on after the last one it took.

        Raises ``LogReadError`` when the file is gone, shrank under what was read or is not
        MCAP, and ``LogLimitError`` when a record breaks the reader's limits."""
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
                yield from self._read(fd, size)
            if self.data_ended:
                self.finished = self.finished or _ends_in_footer(fd, size)
            # Reached only when the caller took every record: the next poll looks only if the
            # file grows (a caller that stopped early gets the rest at the next poll).
            self._size = size
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

    def _check_profile(self, profile: str) -> None:
        """Refuse a file whose header names a profile the follower does not read (any here)."""

    def _metadata(self, body: bytes) -> None:
        """A metadata record's body (nothing a plain follower reads)."""

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
        """Check the magic and the header (``_check_profile``); False while the header is
        not all written."""
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
        self._check_profile(profile)
        self.offset = 17 + length
        self.bytes_read += self.offset
        return True

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

    def _as_read_error(self) -> contextlib.AbstractContextManager[None]:
        return _damage_as_read_error(self.path)


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
