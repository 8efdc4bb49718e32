"""``trace_runtime.reading.growing_file``: a hot segment read as it grows, a poll reading only what
was appended since the last one, and the same cycles as ``reader.Segment`` reads.

(It lives beside the tail tests, tail being what it is for.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.errors import NotHotSegmentError, NotTraceLogError
from trace_runtime.reading.growing_file import GrowingSegment
from trace_runtime.reading.reader import Segment
from trace_runtime.testing import synthetic_cycle


def _logger(root: Path) -> AuditLogger:
    config = LoggerConfig(threaded=False, max_segment_s=3600.0)
    return AuditLogger(root, robot_id="r", config=config)


def _log(log: AuditLogger, cycles: range) -> None:
    for i in cycles:
        p, b, a, e = synthetic_cycle(i)
        log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)


def _keys(cycles: list) -> list[tuple[int, int, dict[str, bytes]]]:
    return [(c.cycle, c.t_ns, c.payloads) for c in cycles]


def test_each_poll_reads_only_what_was_appended_and_the_cycles_are_the_readers(
    tmp_path: Path,
) -> None:
    log = _logger(tmp_path / "root")
    try:
        _log(log, range(50))
        path = next((tmp_path / "root").rglob("*.mcap"))
        growing = GrowingSegment(path)
        first = list(growing.poll())
        assert [c.cycle for c in first] == list(range(50))
        assert growing.session is not None and growing.session.robot_id == "r"
        assert growing.bytes_read == growing.offset <= path.stat().st_size
        assert not growing.data_ended and not growing.finished
        assert list(growing.poll()) == []  # nothing appended: nothing read
        read_before, size_before = growing.bytes_read, path.stat().st_size
        _log(log, range(50, 53))
        appended = path.stat().st_size - size_before
        later = list(growing.poll())
        assert [c.cycle for c in later] == [50, 51, 52]
        assert growing.bytes_read - read_before == appended  # those bytes, no more
    finally:
        log.close()
    rest = list(growing.poll())  # the closing chunk (if any), the data end and the footer
    assert growing.data_ended and growing.finished
    assert growing.offset < path.stat().st_size  # the summary is not read
    whole = list(Segment(path).iter_cycles())
    assert _keys(first + later + rest) == _keys(whole)
    assert sum(len(c.sensors) for c in first + later + rest) == sum(len(c.sensors) for c in whole)


def test_a_chunk_cut_short_at_the_end_is_waited_for(tmp_path: Path) -> None:
    with _logger(tmp_path / "root") as log:
        _log(log, range(20))
    path = next((tmp_path / "root").rglob("*.mcap"))
    data = path.read_bytes()
    full = GrowingSegment(path)
    whole = list(full.poll())
    copy = tmp_path / "r_000000.mcap"
    # every cut: the header half written, a record cut mid-way; then the rest appended
    for cut in (5, 12, 40, len(data) // 3, len(data) // 2 + 7, len(data) - 3):
        copy.write_bytes(data[:cut])
        growing = GrowingSegment(copy)
        before = list(growing.poll())
        assert growing.offset <= cut
        with copy.open("ab") as out:
            out.write(data[cut:])
        after = list(growing.poll())
        assert _keys(before + after) == _keys(whole), cut
        assert growing.finished, cut


def test_what_is_not_a_hot_trace_segment_is_refused(tmp_path: Path) -> None:
    plain = tmp_path / "plain.mcap"
    from mcap.writer import Writer

    with plain.open("wb") as out:
        writer = Writer(out)
        writer.start(profile="ros2", library="test")
        writer.finish()
    with pytest.raises(NotTraceLogError):
        list(GrowingSegment(plain).poll())
    other = tmp_path / "other.mcap"
    other.write_bytes(b"not mcap at all, no")
    with pytest.raises(Exception, match="bad magic"):
        list(GrowingSegment(other).poll())


def test_a_warm_segment_is_left_to_the_reader(tmp_path: Path) -> None:
    from trace_runtime.tiers.compaction import compact

    root = tmp_path / "root"
    with _logger(root) as log:
        _log(log, range(20))
    compact(root, "warm", older_than_ns=0, now_ns=10**12, retention_ns=None)
    warm = next((root / "warm").glob("*.mcap"))
    with pytest.raises(NotHotSegmentError, match="warm segment is read whole"):
        list(GrowingSegment(warm).poll())
