"""``find`` for people: consecutive cycles of one decision are one row (how many, from
when to when, in the log's clock), not one very wide row per cycle; ``--json`` stays one
record per cycle for scripts. The fixture log stops for a person at 104.0-105.9 s (cycles
40-59) and again at 108.0-108.4 s (cycles 80-84)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.outside import cli
from tests.trace_audit.conftest import write_log


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("find")
    root = write_log(where / "logs", robot_id="r1", max_segment_s=3.0)
    assert cli("index", root, "--out", where / "idx").returncode == 0
    return where / "idx"


def test_consecutive_cycles_of_a_decision_are_one_row(index: Path) -> None:
    done = cli("find", index, "--action", "STOP", "--within", "2.0", "--plain")
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if "trace-audit explain" in line]
    assert len(lines) == 2, done.stdout
    first, second = (" ".join(line.split()) for line in lines)
    assert "104.000 s .. 105.900 s" in first and " 20 " in first and "40-59" in first, first
    assert "108.000 s .. 108.400 s" in second and " 5 " in second and "80-84" in second, second
    assert "104000000000" not in done.stdout  # no raw t_ns: times in the log's clock
    assert "25 decisions in 2 runs" in done.stdout, done.stdout
    # what a run says before its explain command (whose path is as long as the log's)
    assert max(len(line.split("trace-audit explain")[0]) for line in lines) < 110, lines


def test_the_json_keeps_one_record_per_cycle(index: Path) -> None:
    done = cli("find", index, "--action", "STOP", "--within", "2.0", "--json")
    rows = json.loads(done.stdout)
    assert [r["cycle"] for r in rows] == [*range(40, 60), *range(80, 85)]
    assert all("t_ns" in r and "explain" in r for r in rows)
