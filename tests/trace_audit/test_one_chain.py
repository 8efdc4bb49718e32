"""One owner per concept: metrics, explain, timeline and info read the same copy of a
segment, apply the same seal check and the same gap rule, and read omitted fields as their
schema defaults. Each test pins a place where two of them used to disagree."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.trace_audit.conftest import write_log
from tests.trace_audit.metrics.test_scan import PERIOD, HandLog, layers, t
from trace_audit.explanation import explain
from trace_audit.info import log_info
from trace_audit.metrics import MetricsConfig, compute_metrics
from trace_audit.selection import per_robot
from trace_audit.transitions import timeline
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE, Gap
from trace_runtime.reading.logset import open_log
from trace_runtime.tiers import compact

# --- one tier policy ---------------------------------------------------------------------------


def _warm_and_lossy_cold(tmp_path: Path) -> Path:
    """A root holding one segment twice: its warm copy and the cold copy made from it."""
    root = write_log(tmp_path / "root")
    compact(root, "warm", older_than_ns=0, retention_ns=None)
    (warm,) = (root / "warm").glob("*.mcap")
    aside = tmp_path / warm.name
    shutil.copy2(warm, aside)
    compact(root, "cold", older_than_ns=0, retention_ns=None, sources=["warm"])
    # as if the cold compaction was interrupted before it removed its source
    shutil.copy2(aside, warm)
    return root


def test_metrics_reads_the_copy_the_log_set_chooses(tmp_path: Path) -> None:
    """metrics used to rank cold before warm while the reader ranked warm first."""
    root = _warm_and_lossy_cold(tmp_path)
    log = open_log(root)
    assert [s.path.parent.name for s in log.segments] == ["warm"]
    report = compute_metrics([root])
    assert report.segments == tuple(str(s.path) for s in log.segments)
    assert [Path(p.split(" (")[0]).parent.name for p in report.skipped_segments] == ["cold"]
    # and explain reads that same copy
    result = explain(root, cycle=50)
    assert result.path == str(root) and result.decision.segment == log.segments[0].path.name
    assert report.overall.decisions == sum(1 for _ in log.iter_cycles())


def test_metrics_reports_an_unreadable_file_and_scores_the_rest(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root")
    (root / "hot" / "junk.mcap").write_bytes(b"not an mcap file at all")
    report = compute_metrics([root])
    assert report.overall.decisions == 100
    (problem,) = report.unreadable
    assert problem.startswith(str(root / "hot" / "junk.mcap") + ": ")


def test_metrics_with_jobs_plans_from_the_same_copies(tmp_path: Path) -> None:
    root = _warm_and_lossy_cold(tmp_path)
    one = compute_metrics([root], MetricsConfig(max_listed=100))
    two = compute_metrics([root], MetricsConfig(max_listed=100, workers=2))
    assert one.segments == two.segments and one.overall == two.overall


# --- one seal check ------------------------------------------------------------------------------


def _seal_log(tmp_path: Path, break_seal: str) -> Path:
    log = HandLog(tmp_path / f"{break_seal}.mcap")
    for i in range(4):
        ref = log.sensor(t(i), {"i": i})
        if i == 2 and break_seal == "reading":
            ref["digest"] = "0" * 64  # the sealed ref names other content than the reading
        if i == 2 and break_seal == "renumbered":
            # a seal that names another cycle than the one it closes in the file
            data = {"cycle": i, "t_ns": t(i), **layers(ref)["action"]}
            log._write("/trace/action", t(i), orjson.dumps(data), i)
            seal = {
                "cycle": 7,
                "t_ns": t(i),
                "digests": {"/trace/action": _sha(orjson.dumps(data))},
                "prev": log.prev_seal,
                "dropped": 0,
            }
            raw = orjson.dumps(seal)
            log._write("/trace/seal", t(i), raw, i)
            log.prev_seal = _sha(raw)
            continue
        if i == 2 and break_seal == "garbage":
            log.cycle(i, t(i), layers(ref), seal=False)
            log._write("/trace/seal", t(i), b"{not json", i)
            log.prev_seal = _sha(b"{not json")
            continue
        log.cycle(i, t(i), layers(ref))
    log.close()
    return log.path


def _sha(data: bytes) -> str:
    import hashlib

    return hashlib.sha256(data).hexdigest()


@pytest.mark.parametrize("break_seal", ["reading", "renumbered", "garbage"])
def test_metrics_and_explain_agree_on_a_seal_the_old_metrics_check_missed(
    tmp_path: Path, break_seal: str
) -> None:
    path = _seal_log(tmp_path, break_seal)
    report = compute_metrics([path], MetricsConfig(max_listed=100))
    assert report.overall.integrity_failed == 1
    (failure,) = [f for f in report.failures if any("integrity" in p for p in f.problems)]
    assert failure.cycle == 2
    assert not explain(path, cycle=2).seal.verified
    for cycle in (0, 1, 3):
        assert explain(path, cycle=cycle).seal.verified


# --- one gap rule ------------------------------------------------------------------------------


def _holes(tmp_path: Path) -> Path:
    """Cycles 0-2, a 3-period hole (3 cycles dropped, declared), then a 1.4-period jitter."""
    log = HandLog(tmp_path / "holes.mcap")
    times = {0: 0, 1: 1, 2: 2, 6: 6, 7: 7, 8: 8.4, 9: 9.4}
    for cycle, periods in times.items():
        at = t(0) + int(periods * PERIOD)
        ref = log.sensor(at, {"i": cycle})
        log.cycle(cycle, at, layers(ref), dropped=3 if cycle == 6 else 0)
    log.close()
    return log.path


def _key(gap: Gap) -> tuple[Any, ...]:
    return (
        gap.after_cycle,
        gap.before_cycle,
        gap.gap_ns,
        gap.missing_cycles,
        gap.declared_dropped,
    )


def test_timeline_info_and_metrics_report_the_same_gaps(tmp_path: Path) -> None:
    path = _holes(tmp_path)
    expected = [(2, 6, 3 * PERIOD, 3, 3)]
    metrics = compute_metrics([path], MetricsConfig(max_listed=100))
    assert [_key(g) for g in metrics.gaps] == expected
    assert [_key(g) for g in timeline(path).gaps] == expected
    info = log_info(path)
    assert [_key(g) for g in info.gaps] == expected
    assert info.gap_ns == metrics.overall.gaps * 0 + 3 * PERIOD
    assert timeline(path).gaps[0].interval_ns == 4 * PERIOD


def test_one_default_tolerance_and_metrics_can_still_override_it(tmp_path: Path) -> None:
    path = _holes(tmp_path)
    assert MetricsConfig().gap_tolerance == DEFAULT_GAP_TOLERANCE
    strict = compute_metrics([path], MetricsConfig(gap_tolerance=0.2, max_listed=10))
    assert [g.after_cycle for g in strict.gaps] == [2, 7]
    assert [g.after_cycle for g in timeline(path, gap_tolerance=0.2).gaps] == [2, 7]
    assert [g.after_cycle for g in log_info(path, gap_tolerance=0.2).gaps] == [2, 7]


def test_two_robots_are_never_compared_with_each_other(tmp_path: Path) -> None:
    """info and timeline used to measure a gap from one robot's last cycle to the next's."""
    root = tmp_path / "fleet"
    root.mkdir()
    r1 = HandLog(root / "r1_000000.mcap", robot="r1")
    for i in range(3):
        r1.cycle(i, t(i), layers(r1.sensor(t(i), {"i": i})))
    r1.close()
    r2 = HandLog(root / "r2_000000.mcap", robot="r2")
    for i in range(3):
        r2.cycle(i, t(i + 10), layers(r2.sensor(t(i + 10), {"i": i})))
    r2.close()
    assert compute_metrics([root]).overall.gaps == 0
    assert log_info(root).gaps == ()
    each = per_robot(open_log(root), timeline)
    assert [(one.robot, one.gaps) for one in each] == [("r1", ()), ("r2", ())]
