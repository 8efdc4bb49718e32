"""MCAP's record framing, as the reader's byte layer parses it: magic, opcodes, the fixed
parts of records, length-prefixed strings, and mapping a file read-only.

Everything here knows MCAP and nothing of TRACE. What a damaged record makes these raise is
``DAMAGE``; the layers above turn it into one ``LogReadError`` naming the file.
"""

from __future__ import annotations

import mmap
import os
import stat
import struct
from pathlib import Path

import zstandard

from trace_runtime.errors import LogReadError

MAGIC = b"\x89MCAP0\r\n"
# Defined here, not by the writer (segment_writer.py), so that reading does not import the
# `mcap` library the writer builds records with (~30 ms of start-up).
CHUNK_TABLE_ATTACHMENT = "trace.chunk_columns"
"""An attachment holding every chunk's start times, then end times, then file offsets, each
a column of little-endian uint64, in time order (written only when the chunks are in time
order, which the logger guarantees unless the robot's clock runs backwards). Readers map it
and bisect it in place instead of parsing one Chunk Index record per chunk (36,000 an hour
at 10 Hz). The Chunk Indexes stay, for every other MCAP tool."""

RECORD_HEADER = struct.Struct("<BQ")
MESSAGE_FIXED = struct.Struct("<HIQQ")
CHUNK_FIXED = struct.Struct("<QQQI")
FOOTER_SIZE = 9 + 20
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 1, 2, 3, 4, 5, 6
OP_CHUNK_INDEX, OP_METADATA, OP_DATA_END = 8, 12, 15
OP_ATTACHMENT_INDEX, OP_STATISTICS, OP_METADATA_INDEX, OP_SUMMARY_OFFSET = 10, 11, 13, 14

DAMAGE = (struct.error, ValueError, KeyError, IndexError, OverflowError, zstandard.ZstdError)
"""What parsing a damaged record raises; never a bug of ours to show as a traceback."""


def damage_reason(err: Exception) -> str:
    return f"damaged MCAP record ({type(err).__name__}: {err})"


def check_fits(body: int, length: int, end: int) -> None:
    """A record whose length runs past its section is damage, not a record."""
    if body + length > end:
        raise struct.error(
            f"record at {body - 9} runs {body + length - end} bytes past its section"
        )


def map_file(path: Path) -> bytes:
    """Map a file read-only: seeks touch only the pages they read, however big the file."""
    try:
        # os.open, not open(): no buffered file object is built for a descriptor that only
        # lives until the mapping is made (a log root opens every segment).
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError as err:
        raise LogReadError(str(path), "no such file") from err
    except IsADirectoryError as err:
        raise LogReadError(str(path), "is a directory, not a segment") from err
    except PermissionError as err:
        raise LogReadError(str(path), "permission denied") from err
    except OSError as err:
        raise LogReadError(str(path), f"cannot read ({err.strerror or err})") from err
    try:
        status = os.fstat(fd)
        if stat.S_ISDIR(status.st_mode):  # os.open opens a directory; open() refused it
            raise LogReadError(str(path), "is a directory, not a segment")
        if status.st_size == 0:
            raise LogReadError(str(path), "empty file")
        return mmap.mmap(fd, 0, access=mmap.ACCESS_READ)  # type: ignore[return-value]
    except OSError as err:
        raise LogReadError(str(path), f"cannot read ({err.strerror or err})") from err
    finally:
        os.close(fd)


def read_str(data: bytes, pos: int) -> tuple[str, int]:
    (length,) = struct.unpack_from("<I", data, pos)
    start = pos + 4
    if start + length > len(data):
        raise struct.error("string runs past the end of the record")
    return data[start : start + length].decode("utf-8", errors="replace"), start + length
