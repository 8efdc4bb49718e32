"""info: robot, time range, cycles, segments and tiers, channels, drops and gaps."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from tests.trace_audit.conftest import PERIOD_NS, T0_NS, stretch, write_log
from trace_audit.info import log_info
from trace_runtime.errors import LogReadError


def test_one_finished_segment(sample_log: Path) -> None:
    r = log_info(sample_log)
    assert r.robots == ("amr-7",)
    assert (r.start_ns, r.end_ns, r.period_ns) == (T0_NS, T0_NS + 99 * PERIOD_NS, PERIOD_NS)
    assert r.cycles == 100 and r.finished and not r.recovered and r.scanned
    assert r.dropped == 0 and r.gaps == () and r.gap_ns == 0
    (seg,) = r.segments
    assert (seg.tier, seg.first_cycle, seg.last_cycle, seg.cycles) == ("hot", 0, 99, 100)
    assert seg.finished and seg.bytes == sample_log.stat().st_size
    assert r.channels["/trace/seal"] == 100 and r.channels["/sensors/lidar"] == 100
    assert r.tiers == {"hot": 1}


def test_a_crashed_segment_is_recovered(
    crashed_log: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        r = log_info(crashed_log)
    assert r.recovered and not r.finished
    assert r.cycles == 100 and r.segments[0].recovered
    assert sum("no footer" in m for m in caplog.messages) == 1


def test_a_log_root_of_rotated_segments_with_drops(tmp_path: Path) -> None:
    root = write_log(
        tmp_path / "root",
        [stretch("clear", 40), stretch("ped_close", 20)],
        max_segment_s=2.0,
        skip=lambda i: i in (10, 11, 33),
    )
    r = log_info(root)
    assert len(r.segments) >= 3 and r.tiers == {"hot": len(r.segments)}
    assert r.cycles == 57 and r.dropped == 3
    assert [(g.after_cycle, g.before_cycle, g.declared_dropped) for g in r.gaps] == [
        (9, 12, 2),
        (32, 34, 1),
    ]
    assert r.gap_ns == 3 * PERIOD_NS
    assert sum(s.cycles for s in r.segments) == 57
    firsts = [s.first_cycle or 0 for s in r.segments]
    assert firsts == sorted(firsts) and firsts[0] == 0
    assert r.segments[-1].last_cycle == 59


def test_quick_reads_only_the_summaries(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root", max_segment_s=3.0, skip=lambda i: i == 50)
    quick = log_info(root, scan=False)
    full = log_info(root)
    assert not quick.scanned and quick.dropped is None and quick.gaps == ()
    assert quick.cycles == full.cycles == 99
    assert [s.last_cycle for s in quick.segments] == [s.last_cycle for s in full.segments]


def test_an_empty_log_is_unreadable(tmp_path: Path) -> None:
    from trace_runtime import AuditLogger, LoggerConfig

    AuditLogger(tmp_path / "e.mcap", robot_id="r", config=LoggerConfig(threaded=False)).close()
    with pytest.raises(LogReadError, match="no decision cycles"):
        log_info(tmp_path / "e.mcap")
