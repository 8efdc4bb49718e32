"""Compaction's own files: partial segments created exclusively, one compactor per root, and
the proof that a file written aside is compaction's own (general file steps are in
``trace_runtime.boundary``).

A partial segment (``<robot>_<segment>.mcap.partial``) is created exclusively and its first
write holds the MCAP header, the ``trace.session`` record and a ``trace.compaction`` metadata
record naming the file it will become (``PartialStream`` holds the writer's first records
until then, so a kill can never leave a header without the marker). ``partial_owner`` reads
that back: only a file with compaction's name and its marker, or an empty one (a kill between
create and first write; it holds nothing to lose), is ever removed as an unfinished write.
"""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from trace_runtime.boundary import create_exclusive, folder_lock
from trace_runtime.errors import LogReadError
from trace_runtime.logger.segment_writer import LIBRARY
from trace_runtime.records import PROFILE
from trace_runtime.segment_names import parse_segment_name

PARTIAL_SUFFIX = ".partial"
LOCK_NAME = ".compact.lock"
PARTIAL_METADATA = "trace.compaction"
"""Metadata record that marks a segment written by compaction; ``partial`` names the file."""

_MAGIC = b"\x89MCAP0\r\n"
_OPCODE_HEADER, _OPCODE_SCHEMA, _OPCODE_CHANNEL, _OPCODE_METADATA = 0x01, 0x03, 0x04, 0x0C
_HEAD_OPCODES = (_OPCODE_HEADER, _OPCODE_SCHEMA, _OPCODE_CHANNEL, _OPCODE_METADATA)
_MARKER_WITHIN = 1 << 22
"""The marker is in the first write: a header, schemas (~50 KB of JSON Schema) and metadata."""

PartialOpener = Callable[[Path], BinaryIO]
"""Creates the stream a partial segment is written to (a plug point: tests inject faults)."""


def partial_path(target: Path) -> Path:
    """Where a segment is written before it is verified and renamed to ``target``."""
    return target.with_name(target.name + PARTIAL_SUFFIX)


def open_partial(path: Path) -> BinaryIO:
    """Create ``path`` for writing; ``FileExistsError`` if anything is there already (a
    link planted at the name included: it is never followed)."""
    return create_exclusive(path)


class PartialStream:
    """A partial segment's stream that holds what is written until ``release``: the header,
    the session record and the marker then reach the file in one write."""

    def __init__(self, file: BinaryIO) -> None:
        self._file = file
        self._held: bytearray | None = bytearray()

    def write(self, data: bytes) -> int:
        if self._held is not None:
            self._held += data
            return len(data)
        return self._file.write(data)

    def flush(self) -> None:
        if self._held is None:
            self._file.flush()

    def release(self) -> None:
        """Write everything held so far in one write; later writes go straight through."""
        held, self._held = self._held, None
        if held:
            self._file.write(bytes(held))
            self._file.flush()

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._file.seek(offset, whence)

    def truncate(self, size: int | None = None) -> int:
        return self._file.truncate(size)

    def fileno(self) -> int:
        return self._file.fileno()

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> PartialStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def partial_owner(path: Path) -> str | None:
    """None when ``path`` is provably an unfinished write of compaction's; otherwise why not.

    Proof: compaction's file name (``<robot>_<segment>.mcap.partial``) and its first records:
    the ``trace.compaction`` record naming this very file; or, for a file cut before that
    record reached the disk (power lost before the first fsync), the segment writer's own
    MCAP header followed by nothing but schema, channel and metadata records, cut short:
    no data. An empty file holds nothing either.
    """
    if not _named_like_a_partial_segment(path.name):
        return "not named like a compaction write"
    try:
        with open(path, "rb") as f:
            head = f.read(_MARKER_WITHIN)
    except OSError as err:
        return f"cannot read it ({err.strerror or err})"
    if not head:
        return None
    marker, cut_before_data = _read_head(head)
    if marker == path.name[: -len(PARTIAL_SUFFIX)]:
        return None
    if marker is None and cut_before_data:
        return None
    return "it does not carry compaction's trace.compaction marker"


def _named_like_a_partial_segment(name: str) -> bool:
    """``name`` is a segment file name (``segment_names``) with the partial suffix."""
    return name.endswith(PARTIAL_SUFFIX) and (
        parse_segment_name(name[: -len(PARTIAL_SUFFIX)]) is not None
    )


def compaction_marker(path: Path) -> str | None:
    """The file name a segment written by compaction was made as (its ``trace.compaction``
    record, read from the file's first records without opening it as a segment), or None."""
    try:
        with open(path, "rb") as f:
            return _read_head(f.read(_MARKER_WITHIN))[0]
    except OSError:
        return None


def _read_head(head: bytes) -> tuple[str | None, bool]:
    """(the ``partial`` the first ``trace.compaction`` record names, or None; whether
    ``head`` is the segment writer's header and records before any data, cut short)."""
    if not head.startswith(_MAGIC[: len(head)]):
        return None, False
    if len(head) <= len(_MAGIC):
        return None, True
    pos = len(_MAGIC)
    try:
        while pos + 9 <= len(head):
            opcode, length = struct.unpack_from("<BQ", head, pos)
            body, end = pos + 9, pos + 9 + length
            if pos == len(_MAGIC) and not _is_writer_header(opcode, head, body):
                return None, False
            if end > len(head):  # cut inside a record (or more than this was read)
                return None, opcode in _HEAD_OPCODES and len(head) < _MARKER_WITHIN
            if opcode == _OPCODE_METADATA:
                name, at = _string(head, body)
                if name == PARTIAL_METADATA:
                    return _map(head, at).get("partial"), False
            elif opcode not in _HEAD_OPCODES:
                return None, False  # data begins: the marker comes before any chunk
            pos = end
    except (struct.error, UnicodeDecodeError):
        return None, False
    return None, len(head) < _MARKER_WITHIN  # records up to the end: the file stops there


def _is_writer_header(opcode: int, head: bytes, body: int) -> bool:
    """The first record is the Header the segment writer writes (profile and library)."""
    if opcode != _OPCODE_HEADER:
        return False
    try:
        profile, at = _string(head, body)
        library, _ = _string(head, at)
    except (struct.error, UnicodeDecodeError):
        return False
    return profile == PROFILE and library == LIBRARY


def _string(data: bytes, pos: int) -> tuple[str, int]:
    (size,) = struct.unpack_from("<I", data, pos)
    end = pos + 4 + size
    if end > len(data):
        raise struct.error("string runs past the record")
    return data[pos + 4 : end].decode(), end


def _map(data: bytes, pos: int) -> dict[str, str]:
    (size,) = struct.unpack_from("<I", data, pos)
    pos, end = pos + 4, pos + 4 + size
    out: dict[str, str] = {}
    while pos < end:
        key, pos = _string(data, pos)
        value, pos = _string(data, pos)
        out[key] = value
    return out


def root_lock(root: Path) -> contextlib.AbstractContextManager[None]:
    """Hold an exclusive lock on ``root`` for one compaction (released even on kill -9)."""
    return folder_lock(
        root / LOCK_NAME, held=f"{root}: another compaction is running on this log root"
    )


def require_root(root: Path) -> None:
    """``root`` is a folder, or a ``LogReadError`` that says what it is instead: a segment
    file handed where a root belongs is the common slip, and the message says so."""
    if root.is_dir():
        return
    if root.is_file():
        what = "a segment file" if root.suffix == ".mcap" else "a file"
        raise LogReadError(str(root), f"{what}, not a log root (a folder with hot/ warm/ cold/)")
    raise LogReadError(str(root), "not a log root (no such directory)")
