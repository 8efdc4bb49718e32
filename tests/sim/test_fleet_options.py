"""``trace-sim run --robot-id`` and ``--start``: simulated robots sharing one log root, on a
sim clock or a wall clock, run from the outside as a user runs them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import pytest

from sim import read_truth
from tests.outside import REPO, one_line
from trace_runtime import open_log

WALL_START = "2026-05-04T06:00:00Z"
WALL_START_NS = int(datetime(2026, 5, 4, 6, tzinfo=UTC).timestamp()) * 1_000_000_000


def sim_cli(*args: str | Path) -> subprocess.CompletedProcess[str]:
    """``trace-sim ARGS`` in a fresh process of this checkout."""
    return subprocess.run(
        [sys.executable, "-m", "evaluation.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=120,
    )


def _run(root: Path, robot: str, *extra: str) -> dict[str, object]:
    done = sim_cli("run", "--duration", "3s", "--robot-id", robot, "--out", root, "--json", *extra)
    assert done.returncode == 0, done.stderr
    result: dict[str, object] = json.loads(done.stdout)
    return result


def test_three_robots_share_one_root_each_with_its_own_chain_and_truth(tmp_path: Path) -> None:
    root = tmp_path / "fleet"
    results = [_run(root, f"amr-{n}", "--seed", str(n)) for n in (1, 2, 3)]
    assert sorted(p.name for p in (root / "hot").iterdir()) == [
        "amr-1_000000.mcap",
        "amr-2_000000.mcap",
        "amr-3_000000.mcap",
    ]
    log = open_log(root)
    assert log.robots == ["amr-1", "amr-2", "amr-3"]
    for n, result in zip((1, 2, 3), results, strict=True):
        (segment,) = log.segments_of(f"amr-{n}")
        assert segment.session.clock == "sim"
        cycles = list(segment.iter_cycles())
        assert cycles[0].cycle == 0 and cycles[0].t_ns == 0  # the default: a sim clock from 0
        truth = Path(str(result["truth"]))
        assert truth.name == f"sim-truth-amr-{n}.jsonl"
        assert read_truth(truth) is not None


@pytest.mark.parametrize(
    ("start", "clock", "first_ns"),
    [(WALL_START, "system", WALL_START_NS), ("3600", "sim", 3600 * 10**9), ("0.25", "sim", 25e7)],
)
def test_start_sets_the_clock_and_the_first_time(
    tmp_path: Path, start: str, clock: str, first_ns: float
) -> None:
    _run(tmp_path, "amr-9", "--start", start)
    log = open_log(tmp_path)
    (segment,) = log.segments
    assert segment.session.clock == clock
    times = [c.t_ns for c in segment.iter_cycles()]
    assert times[0] == int(first_ns)
    assert times[1] - times[0] == 100_000_000


def test_an_iso_start_with_an_offset_is_the_same_utc_moment(tmp_path: Path) -> None:
    _run(tmp_path, "amr-9", "--start", "2026-05-04T08:00:00+02:00")
    assert next(open_log(tmp_path).iter_cycles()).t_ns == WALL_START_NS


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--start", "soon"], "bad --start 'soon'"),
        (["--start", "2026-05-04T06:00:00"], "needs a zone"),
        (["--start", "1990-01-01T00:00:00Z"], "before 2000"),
        (["--start", "-5"], "seconds >= 0"),
        (["--robot-id", "a/b"], "robot_id must be a simple name"),
    ],
)
def test_a_bad_start_or_robot_id_is_one_line_exit_2(
    tmp_path: Path, args: list[str], needle: str
) -> None:
    done = sim_cli("run", "--duration", "1s", "--out", tmp_path / "r", *args)
    one_line(done, 2, "trace-sim:", needle)
    assert not (tmp_path / "r" / "hot").exists()
