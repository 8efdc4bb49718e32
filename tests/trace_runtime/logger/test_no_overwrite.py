"""A logger never writes over a log that exists: a single-file path that is taken is refused
when the logger is made (a set-up error naming the file and the way out), with the file's
bytes untouched; ``trace-sim run --out`` and the minimal example refuse the same way, from
the outside."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import REPO
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.errors import UsageError
from trace_runtime.testing import synthetic_cycle


def _log(path: Path, cycles: int) -> None:
    with AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=False)) as logger:
        for i in range(cycles):
            p, b, a, e = synthetic_cycle(i)
            logger.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)


def _run(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
    )


@pytest.mark.parametrize("threaded", [False, True])
def test_a_logger_refuses_a_file_that_exists_and_leaves_it_as_it_was(
    tmp_path: Path, threaded: bool
) -> None:
    path = tmp_path / "run.mcap"
    _log(path, 5)
    before = path.read_bytes()
    with pytest.raises(UsageError, match=r"run\.mcap exists.*log root"):
        AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=threaded))
    assert path.read_bytes() == before
    (tmp_path / "notes.mcap").write_bytes(b"someone's file\n")
    with pytest.raises(UsageError, match=r"notes\.mcap exists"):
        AuditLogger(tmp_path / "notes.mcap", robot_id="r")
    assert (tmp_path / "notes.mcap").read_bytes() == b"someone's file\n"
    # the refused logger let go of its lock: the next one, on a new name, starts
    _log(tmp_path / "run2.mcap", 3)


def test_a_log_root_is_continued_not_overwritten(tmp_path: Path) -> None:
    _log(tmp_path / "root", 5)
    _log(tmp_path / "root", 5)
    assert [c.cycle for c in open_log(tmp_path / "root").iter_cycles()] == list(range(10))


def test_trace_sim_refuses_an_out_file_that_exists_unless_forced(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    args = ("-c", "from evaluation.entry import main; main()", "run", "--cycles", "5", "--out", out)
    first = _run(*args)
    assert first.returncode == 0, first.stderr
    before = out.read_bytes()
    again = _run(*args, "--seed", "7")
    assert again.returncode == 4, again.stderr
    assert again.stderr.count("\n") == 1 and "Traceback" not in again.stderr
    assert str(out) in again.stderr and "--force" in again.stderr
    assert out.read_bytes() == before
    forced = _run(*args, "--seed", "7", "--force")
    assert forced.returncode == 0, forced.stderr
    assert out.read_bytes() != before


def test_the_minimal_example_run_twice_keeps_the_first_log(tmp_path: Path) -> None:
    out = tmp_path / "robot.mcap"
    example = REPO / "examples" / "minimal_robot.py"
    assert _run(example, "--out", out, "--cycles", "5").returncode == 0
    before = out.read_bytes()
    again = _run(example, "--out", out, "--cycles", "5")
    assert again.returncode == 2 and "Traceback" not in again.stderr, again.stderr
    assert again.stderr.count("\n") == 1 and "robot.mcap exists" in again.stderr
    assert out.read_bytes() == before
