"""Unknown is not zero: a decision whose cited evidence lies in a recording that cannot be read
has ET, ET_partial and TCS unknown (None, null, "?"), counted apart; a broken one is a
finding. The log and its rosbag2 recordings are written by a real logger and by ``rosbags``
(tests/trace_audit/ros2_root.py); the recordings are found where the log declares them."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.ros2_root import (
    CYCLES,
    NO_ALTERNATIVES_EVERY,
    PERIOD_NS,
    REAR_EVERY,
    T0_NS,
    break_message,
    copy_site,
    write_root,
)
from trace_audit.cli import app
from trace_audit.metrics import MetricsConfig, compute_metrics

runner = CliRunner()
REAR_CITED = len(range(0, CYCLES, REAR_EVERY))
EPOCH_SECONDS = re.compile(r"1777885\d{3}")
"""The wall-clock times of the fixture as raw epoch seconds: never shown to a person."""


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_root(tmp_path_factory.mktemp("site"))


def _without(root: Path, tmp_path: Path, bag: str) -> Path:
    moved = copy_site(root, tmp_path / "moved")
    shutil.rmtree(moved.parent / bag)
    return moved


def test_declared_recordings_resolve_without_a_flag(root: Path) -> None:
    report = compute_metrics([root])
    assert report.external_refs == {"resolved": CYCLES + REAR_CITED}
    o = report.overall
    assert (o.et.mean, o.fully_traceable, o.unknown) == (1.0, CYCLES, 0)
    assert o.tcs.mean is not None and o.tcs.n == CYCLES


def test_a_missing_recording_makes_its_decisions_unknown_not_zero(
    root: Path, tmp_path: Path
) -> None:
    moved = _without(root, tmp_path, "rear_bag")
    o = compute_metrics([moved]).overall
    assert o.unknown == REAR_CITED
    # the decisions that are known are fully traceable: the unknown ones are not averaged in
    assert (o.et.mean, o.et.n, o.fully_traceable) == (1.0, CYCLES - REAR_CITED, CYCLES - REAR_CITED)
    assert o.tcs.n == CYCLES - REAR_CITED and o.et_partial.n == CYCLES - REAR_CITED
    shown = runner.invoke(app, ["metrics", str(moved)])
    assert shown.exit_code == 0, shown.output
    text = " ".join(shown.stdout.split())
    assert f"{REAR_CITED} unknown (recording rear_bag not found" in text, text
    data = json.loads(runner.invoke(app, ["metrics", str(moved), "--json"]).stdout)
    assert data["overall"]["unknown"] == REAR_CITED
    assert data["overall"]["et"]["mean"] == 1.0


def test_every_decision_unknown_shows_no_number(root: Path, tmp_path: Path) -> None:
    moved = _without(root, tmp_path, "front_bag")
    report = compute_metrics([moved])
    o = report.overall
    assert o.unknown == CYCLES and o.et.mean is None and o.tcs.mean is None
    assert o.dr == pytest.approx(1 - len(range(3, CYCLES, NO_ALTERNATIVES_EVERY)) / CYCLES)
    listed = {f.cycle: f for f in report.failures}
    assert set(listed) == set(range(3, CYCLES, NO_ALTERNATIVES_EVERY))
    assert all(f.et is None and f.et_partial is None for f in listed.values())
    data = json.loads(runner.invoke(app, ["metrics", str(moved), "--json"]).stdout)
    assert data["overall"]["et"]["mean"] is None and data["overall"]["tcs"]["mean"] is None
    assert data["table_ii"]["ET_mean"] is None and data["table_ii"]["unknown"] == CYCLES
    shown = runner.invoke(app, ["metrics", str(moved), "--failures"])
    assert shown.exit_code == 0, shown.output
    text = " ".join(shown.stdout.split())
    assert "0.0" not in text.split("Auditability metrics of the")[1].split("fully")[0], text
    assert f"{CYCLES} unknown (recording front_bag not found" in text
    assert "ET ?" in text and "ET 0.00" not in text
    assert not EPOCH_SECONDS.search(shown.stdout), shown.stdout
    assert "2026-05-04T09:01:29.300Z" in shown.stdout  # cycle 3, in the log's clock


def test_a_broken_message_is_a_finding_not_unknown(root: Path, tmp_path: Path) -> None:
    moved = copy_site(root, tmp_path / "moved")
    break_message(moved.parent / "front_bag", T0_NS + 7 * PERIOD_NS)
    report = compute_metrics([moved])
    assert report.external_refs == {"broken": 1, "resolved": CYCLES + REAR_CITED - 1}
    o = report.overall
    assert o.unknown == 0 and o.fully_traceable == CYCLES - 1
    [seven] = [f for f in report.failures if f.cycle == 7]
    assert seven.et == 0.0


def test_evidence_overrides_a_declared_recording_that_moved(root: Path, tmp_path: Path) -> None:
    moved = _without(root, tmp_path, "front_bag")
    given = compute_metrics([moved], MetricsConfig(evidence=(str(root.parent / "front_bag"),)))
    assert given.overall.unknown == 0 and given.overall.et.mean == 1.0


def test_the_index_and_find_store_null_for_unknown(root: Path, tmp_path: Path) -> None:
    pytest.importorskip("duckdb")
    moved = _without(root, tmp_path, "rear_bag")
    index = tmp_path / "index"
    built = runner.invoke(app, ["index", str(moved), "--out", str(index)])
    assert built.exit_code == 0, built.output
    found = runner.invoke(app, ["find", str(index), "--json"])
    assert found.exit_code == 0, found.output
    rows = json.loads(found.stdout)
    by_cycle = {r["cycle"]: r for r in rows}
    assert len(by_cycle) == CYCLES
    assert {c for c, r in by_cycle.items() if r["et"] is None} == set(range(0, CYCLES, REAR_EVERY))
    assert all(r["et"] == 1.0 for c, r in by_cycle.items() if c % REAR_EVERY)
    people = runner.invoke(app, ["find", str(index), "--where", "d.cycle = 5"])
    assert people.exit_code == 0, people.output
    [header, _rule, row] = people.stdout.splitlines()[:3]
    # find's runs end with the lowest ET, then the explain command
    assert header.split("explain")[0].split()[-1] == "ET", header
    assert row.split("trace-audit explain")[0].split()[-1] == "?", row
    fleet = json.loads(runner.invoke(app, ["metrics", "--index", str(index), "--json"]).stdout)
    assert fleet["overall"]["unknown"] == REAR_CITED
    assert fleet["overall"]["et"]["mean"] == 1.0
