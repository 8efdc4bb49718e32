"""One MCAP file's chunk table: where each chunk is and what time it covers, sorted by start
time for seeks, built from whichever index agrees with the data.

Three sources, each a hint checked against the bytes (``McapFile`` tries them in order):
the writer's compact ``trace.chunk_columns`` attachment (mapped in place: no copy, no parse),
MCAP's Chunk Index records, and the rows a walk of the data section found.
"""

from __future__ import annotations

import array
import bisect
import itertools
import struct
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from trace_runtime.encoding.mcap_records import (
    OP_CHUNK,
    OP_CHUNK_INDEX,
    RECORD_HEADER,
    check_fits,
    read_str,
)

__all__ = ["ChunkInfo", "ChunkTable", "chunk_at", "chunk_index_rows"]

Row = tuple[int, int, int]
"""(start ns, end ns, file offset) of one chunk."""


@dataclass(frozen=True, slots=True)
class ChunkInfo:
    """Where a chunk is and what time it covers."""

    offset: int
    length: int
    start_ns: int
    end_ns: int


def chunk_at(data: bytes, offset: int, start_ns: int, end_ns: int) -> bool:
    """Whether a chunk record with this time range starts at ``offset``."""
    return (
        offset + 25 <= len(data)
        and data[offset] == OP_CHUNK
        and struct.unpack_from("<QQ", data, offset + 9) == (start_ns, end_ns)
    )


def chunk_index_rows(data: bytes, begin: int, end: int) -> list[Row]:
    """The rows of the Chunk Index records between ``begin`` and ``end``."""
    rows = []
    pos = begin
    while pos + 9 <= end:
        opcode, length = RECORD_HEADER.unpack_from(data, pos)
        if opcode == OP_CHUNK_INDEX:
            start, stop, offset = struct.unpack_from("<QQQ", data, pos + 9)
            rows.append((start, stop, offset))
        pos += 9 + length
    return rows


class ChunkTable:
    """Start times, end times and file offsets of every chunk, sorted by start time."""

    __slots__ = ("_sorted_offsets", "ends", "ends_sorted", "offsets", "starts", "starts_in_order")

    def __init__(
        self,
        starts: Sequence[int],
        ends: Sequence[int],
        offsets: Sequence[int],
        *,
        ends_sorted: bool,
        starts_in_order: bool,
    ) -> None:
        self.starts, self.ends, self.offsets = starts, ends, offsets
        self.ends_sorted = ends_sorted
        self.starts_in_order = starts_in_order
        """Whether sorting by start time kept the chunks in file order."""
        self._sorted_offsets: list[int] | None = None

    @classmethod
    def from_rows(cls, rows: list[Row]) -> ChunkTable:
        """A table from index rows in any order. Chunks that start together stay in file
        order; a chunk named twice is listed once (else every read would repeat it)."""
        # Timsort on sorted input is one linear pass in C: cheap enough to check always.
        by_time = sorted({r[2]: r for r in rows}.values(), key=lambda r: (r[0], r[2]))
        starts, ends = [r[0] for r in by_time], [r[1] for r in by_time]
        offsets = [r[2] for r in by_time]
        return cls(
            starts,
            ends,
            offsets,
            ends_sorted=ends == sorted(ends),
            starts_in_order=offsets == sorted(offsets),
        )

    @classmethod
    def from_attachment(cls, data: bytes, offset: int, expected: int | None) -> ChunkTable | str:
        """The writer's chunk columns at ``offset``, mapped in place; or why they do not
        describe this file."""
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
            if not chunk_at(data, offsets[i], column[i], column[count + i]):
                return (
                    f"no chunk of the times it lists at offset {offsets[i]} (a copy of "
                    "another file's)"
                )
        # Our writer's own table: written in file order, one chunk per batch in time order.
        return cls(
            column[:count],
            column[count : 2 * count],
            offsets,
            ends_sorted=True,
            starts_in_order=True,
        )

    def columns(self) -> tuple[Sequence[int], Sequence[int], Sequence[int]]:
        return self.starts, self.ends, self.offsets

    def offsets_in_range(self, start_ns: int | None, end_ns: int | None) -> list[int]:
        """File offsets of the chunks that may hold messages in the range, in file order."""
        starts, ends, offsets = self.starts, self.ends, self.offsets
        hi = len(starts) if end_ns is None else bisect.bisect_right(starts, end_ns)
        lo = 0
        if start_ns is not None and self.ends_sorted:
            lo = bisect.bisect_left(ends, start_ns)
        chosen = [offsets[i] for i in range(lo, hi) if start_ns is None or ends[i] >= start_ns]
        return chosen if self.starts_in_order else sorted(chosen)

    def offsets_back_from(self, t_ns: int) -> Iterator[int]:
        """File offsets of the chunks that start at or before ``t_ns``, the latest start
        first: a seek looks at one or two of them, so they are produced one at a time."""
        offsets = self.offsets
        for i in range(bisect.bisect_right(self.starts, t_ns) - 1, -1, -1):
            yield offsets[i]

    def file_order(self) -> Sequence[int]:
        """Every chunk's offset in file order."""
        if self.starts_in_order:
            return self.offsets
        if self._sorted_offsets is None:
            self._sorted_offsets = sorted(self.offsets)
        return self._sorted_offsets

    def span(self, offset: int) -> tuple[int, int] | None:
        """The time range of the chunk at ``offset`` (None if it is not in the table)."""
        for i, o in enumerate(self.offsets):
            if o == offset:
                return self.starts[i], self.ends[i]
        return None
