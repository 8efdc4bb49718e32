"""``trace-audit metrics``: tables, JSON, failures, thresholds and exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.metrics.test_scan import HandLog, layers, t
from trace_audit.cli import app


@pytest.fixture
def small_log(tmp_path: Path) -> Path:
    log = HandLog(tmp_path / "small.mcap")
    for i in range(8):
        if i == 4:
            continue  # a gap
        ref = log.sensor(t(i), {"i": i})
        log.cycle(
            i,
            t(i),
            layers(None if i == 6 else ref, scenario="a" if i < 3 else "b", truncated=i == 7),
            dropped=1 if i == 5 else 0,
        )
    log.close()
    return log.path


def run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, ["metrics", *args])
    return result.exit_code, result.stdout, result.stderr


def test_help_states_the_definitions_and_an_example() -> None:
    code, out, _ = run("--help")
    assert code == 0
    for words in (
        "ET_partial",
        "Expected depth 5",
        "gap tolerance",
        "DR(d)",
        "TCS(d)",
        "trace-audit metrics run.mcap --by scenario",
    ):
        assert words in out


def test_tables_with_counts(small_log: Path) -> None:
    code, out, _ = run(str(small_log), "--by", "scenario", "--plain")
    assert code == 0
    assert "Auditability metrics of the" in out and "Per scenario" in out
    assert "6/7" in out  # fully traceable decisions, beside the percentage
    assert "not logged" in out  # no per-cycle logging time in this log
    assert "across decisions" in out and "Across 2 scenarios" in out


def test_json_holds_both_tables(small_log: Path) -> None:
    code, out, _ = run(str(small_log), "--by", "scenario", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["overall"]["decisions"] == 7
    assert data["table_ii"]["fully_traceable"] == 6
    assert data["table_ii"]["gaps"] == 1
    assert data["overall"]["declared_dropped"] == 1
    assert [row["group"] for row in data["table_iii"]] == ["a", "b"]
    assert data["table_iii"][1]["not_reconstructable"] == 1
    assert data["definitions"]["expected_depth"].startswith("5 for a factor")
    assert "failures" not in data


def test_failures_list_cycle_time_and_what_is_missing(small_log: Path) -> None:
    code, out, _ = run(str(small_log), "--failures", "--plain")
    assert code == 0
    assert "cycle 6  t=5.600 s" in out and "evidence_ref missing" in out
    assert "cycle 7" in out and "DR: rationale truncated" in out
    assert "after cycle 3" in out and "1 declared dropped" in out


def test_fail_under_exits_1_and_says_which(small_log: Path) -> None:
    code, _, err = run(str(small_log), "--fail-under", "ET=0.9,TC=0.5", "--plain")
    assert code == 1
    assert "ET" in err and "TC" not in err.split("below threshold:")[1]
    code, _, _ = run(str(small_log), "--fail-under", "ET=0.5", "--plain")
    assert code == 0


@pytest.mark.parametrize(
    "args", [["--by", "weekday"], ["--fail-under", "ET=95"], ["--tcs-weights", "x=1"]]
)
def test_bad_options_exit_2(small_log: Path, args: list[str]) -> None:
    code, _, err = run(str(small_log), *args)
    assert code == 2
    assert err.startswith("trace-audit: ") and "Traceback" not in err


def test_unreadable_input_exits_3(tmp_path: Path) -> None:
    code, _, err = run(str(tmp_path / "missing.mcap"))
    assert code == 3 and "no such file" in err
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    code, _, err = run(str(junk))
    assert code == 3 and err.count("\n") == 1


def test_jobs_gives_the_same_json(small_log: Path) -> None:
    _, one, _ = run(str(small_log), "--json")
    _, two, _ = run(str(small_log), "--json", "--jobs", "2")
    a, b = json.loads(one), json.loads(two)
    for data in (a, b):
        data.pop("elapsed_s")
        data.pop("cycles_per_s")
    assert a == b


def test_empty_directory_is_unreadable(tmp_path: Path) -> None:
    code, _, err = run(str(tmp_path))
    assert code == 3 and "no .mcap segments" in err
