"""``SegmentWriter``: one MCAP segment written a batch of whole cycles per chunk; after a
write that fails and cannot be rolled back, the file's real end says whether the batch is in
it as a reader recovers it."""

from __future__ import annotations

import errno
import io
from pathlib import Path
from typing import Any

import pytest

from tests.trace_runtime.full_disk import FullDisk
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.errors import SegmentWriteError
from trace_runtime.logger.mcap_out import OutMessage
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.session import SessionInfo

SESSION = SessionInfo(robot_id="r", period_ns=100_000_000)
BATCH = [(1, 0, 10, b'{"a":1}'), (2, 0, 10, b'{"b":2}'), (1, 1, 20, b'{"a":3}')]


def _segment_bytes(messages: list[OutMessage] | list[tuple[int, int, int, bytes]]) -> bytes:
    stream = io.BytesIO()
    session = SessionInfo(robot_id="r", period_ns=100_000_000)
    writer = SegmentWriter(stream, session)
    writer.write_batch(messages)
    writer.finish()
    return stream.getvalue()


def test_write_batch_takes_plain_tuples_and_out_messages_alike() -> None:
    rows = [(1, 0, 10, b'{"a":1}'), (2, 0, 10, b'{"b":2}'), (1, 1, 20, b'{"a":3}')]
    assert _segment_bytes([OutMessage(*row) for row in rows]) == _segment_bytes(rows)


def _failing_batch(stream: Any) -> tuple[SegmentWriteError, int]:
    """Write one good batch, then ``BATCH`` again into a stream that fails at its 4th write
    (header, session metadata, first batch, this one): the error, and where the file's good
    part ended before it."""
    writer = SegmentWriter(stream, SESSION)
    writer.write_batch(BATCH)
    good = writer.offset
    with pytest.raises(SegmentWriteError) as caught:
        writer.write_batch(BATCH)
    writer.close()
    return caught.value, good


def _messages_read(path: Path) -> int:
    return sum(1 for _ in McapFile(path).iter_messages())


def test_kept_says_exactly_whether_a_reader_recovers_the_batch(tmp_path: Path) -> None:
    """For every number of the failing write's bytes that reach the file, with the rollback
    failing, ``kept`` is True exactly when a reader of the file finds the batch."""
    sizes: list[int] = []

    def lands(landed: int) -> Any:
        def part(n: int) -> int:
            sizes.append(n)
            return min(n, landed)

        return part

    kept: list[bool] = []
    for landed in range(10_000):
        path = tmp_path / f"{landed}.mcap"
        err, good = _failing_batch(FullDisk(fails_at=4, lands=lands(landed)).open(path))
        assert not err.rolled_back
        assert err.kept == (_messages_read(path) == 2 * len(BATCH)), landed
        assert err.written == (path.stat().st_size - good if err.kept else 0)
        kept.append(err.kept)
        if landed >= sizes[-1]:
            break  # the whole write landed
    # Not kept while the chunk is cut, kept from the byte that completes it on (the
    # message indexes after it need not be there).
    first = kept.index(True)
    assert 0 < first < len(kept) - 1 and all(kept[first:]) and not any(kept[:first])


class _ShortWrites(io.FileIO):
    """A file on a filling disk, as write(2) sees it: a write that does not fit lands what
    fits and returns that count; the next ``refusals`` writes raise ENOSPC; then room
    again (another process freed space)."""

    def __init__(self, path: Path, *, fail_at: int, fits: int, refusals: int) -> None:
        super().__init__(path, "w")
        self.calls, self.fail_at, self.fits, self.refusals = 0, fail_at, fits, refusals

    def write(self, data: Any) -> int:
        self.calls += 1
        if self.calls == self.fail_at:
            return super().write(bytes(data)[: self.fits])
        if self.fail_at < self.calls <= self.fail_at + self.refusals:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def test_a_short_write_on_an_unbuffered_stream_is_finished_not_ignored(tmp_path: Path) -> None:
    path = tmp_path / "short.mcap"
    raw = _ShortWrites(path, fail_at=4, fits=7, refusals=0)
    writer = SegmentWriter(raw, SESSION)
    writer.write_batch(BATCH)
    writer.write_batch(BATCH)  # lands 7 bytes, then the rest in a second write
    writer.close()
    assert _messages_read(path) == 2 * len(BATCH)


def test_a_short_write_then_enospc_is_rolled_back(tmp_path: Path) -> None:
    path = tmp_path / "rolled.mcap"
    err, _ = _failing_batch(_ShortWrites(path, fail_at=4, fits=7, refusals=1))
    assert err.rolled_back and not err.kept


@pytest.mark.parametrize("room_at_close", [True, False], ids=["room at close", "still full"])
def test_what_a_buffered_stream_held_is_counted_once_it_is_closed(
    tmp_path: Path, room_at_close: bool
) -> None:
    """A buffered stream cannot seek (the rollback) without writing what it holds first, so
    on a full disk the rollback fails; its close then writes the rest if there is room. The
    file's end is read after that close, so the batch is kept exactly when it got there."""
    path = tmp_path / "buffered.mcap"
    # Raw writes: 1 the header, 2 the session metadata, 3 the first batch, 4 the second
    # batch's flush (lands 7 bytes), 5 the rest of that flush, 6 the rollback's seek
    # (refused: the disk is full), 7 the close.
    raw = _ShortWrites(path, fail_at=4, fits=7, refusals=2 if room_at_close else 3)
    stream = io.BufferedWriter(raw, buffer_size=1 << 20)
    writer = SegmentWriter(stream, SESSION)
    writer.write_batch(BATCH)
    calls = raw.calls
    with pytest.raises(SegmentWriteError) as caught:
        writer.write_batch(BATCH)
    assert raw.calls == calls + 4
    err = caught.value
    assert stream.closed and not err.rolled_back
    assert err.kept == room_at_close
    assert _messages_read(path) == len(BATCH) * (2 if room_at_close else 1)


def test_a_stream_without_a_descriptor_cannot_be_measured_so_the_batch_is_lost() -> None:
    class Full(io.BytesIO):
        calls = 0

        def write(self, data: Any) -> int:
            self.calls += 1
            if self.calls > 3:
                super().write(data)  # the whole batch lands, but nobody can tell
                raise OSError(errno.ENOSPC, "No space left on device")
            return super().write(data)

        def truncate(self, size: Any = None) -> int:
            raise OSError(errno.ENOSPC, "No space left on device")

    err, _ = _failing_batch(Full())
    assert not err.rolled_back and not err.kept
