"""Words a user reads, checked from the outside: a program or group run without a command
shows its help on stdout; trace-sim's usage errors are one line like trace-audit's; the
demo's counts say what they count; the fleet index's title does not stutter."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import REPO, cli, one_line
from tests.trace_audit.conftest import write_log


def _sim(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", "from evaluation.entry import main; main()", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "200"},
        timeout=300,
    )


@pytest.mark.parametrize("args", [(), ("witness",)])
def test_trace_audit_without_a_command_prints_its_help_on_stdout(args: tuple[str, ...]) -> None:
    done = cli(*args)
    assert done.returncode == 2 and done.stderr == "", done.stderr
    head = done.stdout.splitlines()[0]  # the program's name is python -m's here
    assert head.startswith("Usage: ") and head.endswith(
        " ".join((*args, "[OPTIONS] COMMAND [ARGS]..."))
    )
    assert "Commands:" in done.stdout


def test_trace_sim_without_a_command_and_its_usage_errors() -> None:
    done = _sim()
    assert done.returncode == 2 and done.stderr == "", done.stderr
    assert done.stdout.startswith("Usage: ") and "[OPTIONS] COMMAND" in done.stdout
    assert "Commands:" in done.stdout
    one_line(_sim("run", "--cycles", "x"), 2, "trace-sim: ", "--cycles", "trace-sim run --help")
    one_line(_sim("bogus"), 2, "trace-sim: ", "bogus")
    one_line(_sim("run", "--faults", "maybe", "--out", "x.mcap"), 2, "trace-sim: ", "--faults")


def test_the_demo_says_what_each_count_counts(tmp_path: Path) -> None:
    done = _sim("run", "--cycles", "40", "--seed", "42", "--out", tmp_path / "run.mcap")
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "decided" in out and "written to the log" in out
    assert "cycles per command" in out and "STOP cycles" in out
    assert "stops (changes to STOP)" in out and "STOPs" not in out


def test_the_fleet_index_title_names_its_folder_once(tmp_path: Path) -> None:
    log = write_log(tmp_path / "run.mcap")
    done = cli("index", log, "--out", tmp_path / "index", "--plain")
    assert done.returncode == 0, done.stderr
    assert "index index" not in done.stdout.lower()
    assert f"Fleet index in {tmp_path / 'index'}" in " ".join(done.stdout.split())
