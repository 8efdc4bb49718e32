"""A ROS 2 robot cites a message by its stamp; rosbag2 records it at its receive time, a
little later. The ref resolves by its digest (PROFILE §11), and every command counts it as
resolved, as a ref by the exact time is: traceable, never MISSING (found from outside: ET 0
beside "digest verified")."""

from __future__ import annotations

import json
from pathlib import Path

from tests.outside import cli
from tests.trace_runtime.logger.test_recording_seals import record, run_robot


def _et(root: Path) -> float:
    done = cli("metrics", root, "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["external_refs"] == {"resolved": 30}, report["external_refs"]
    return float(report["overall"]["et"]["mean"])


def test_refs_by_stamp_are_traceable_everywhere(tmp_path: Path) -> None:
    bag = tmp_path / "ward_bag"
    assert record(bag, "--messages", "30").wait(timeout=60) == 0
    by_stamp, exact = tmp_path / "by_stamp", tmp_path / "exact"
    run_robot(by_stamp, bag, 40, cited=30, stamp_early_ns=3_000_000)
    run_robot(exact, bag, 40, cited=30)
    assert _et(by_stamp) == _et(exact)
    explained = cli("explain", by_stamp, "--cycle", "5")
    assert explained.returncode == 0, explained.stderr
    assert "[ok] sensor reading: ward_bag:/scan" in explained.stdout
    assert "[MISSING] sensor reading: ward_bag" not in explained.stdout
    assert "recorded +0.003 s from the ref's time" in explained.stdout
    dot = cli("export", by_stamp, "--cycle", "5", "--format", "dot")
    assert dot.returncode == 0, dot.stderr
    assert "ward_bag:/scan" in dot.stdout and "MISSING\\nward_bag" not in dot.stdout
