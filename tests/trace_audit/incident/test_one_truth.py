"""One truth per page: the report's scene, entity table, evidence section and auditability
figures, and the dot, mermaid and Foxglove exports, say the same about evidence in a rosbag2
recording, for a recording that resolves, one with a changed message and one not there.

The log and its recordings come from a real logger and ``rosbags``
(tests/trace_audit/ros2_root.py); the recordings are found where the log declares them."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.ros2_root import (
    PERIOD_NS,
    T0_NS,
    break_message,
    copy_site,
    write_root,
)
from trace_audit.cli import app
from trace_audit.export import export_decision
from trace_audit.incident import build_report

CYCLE = 10
"""Cites person_1 in front_bag and cart_1 in rear_bag (every fifth cycle cites both)."""
EXPECTED = {
    "resolved": {"person_1": "resolved", "cart_1": "resolved"},
    "broken": {"person_1": "broken", "cart_1": "resolved"},
    "missing": {"person_1": "unresolved", "cart_1": "resolved"},
}
runner = CliRunner()


@pytest.fixture(scope="module")
def roots(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("sites")
    root = write_root(base / "resolved")
    broken = copy_site(root, base / "broken")
    break_message(broken.parent / "front_bag", T0_NS + CYCLE * PERIOD_NS)
    missing = copy_site(root, base / "missing")
    shutil.rmtree(missing.parent / "front_bag")
    return {"resolved": root, "broken": broken, "missing": missing}


def _by_entity(pairs: list[tuple[str, str]]) -> dict[str, str]:
    out: dict[str, str] = {}
    for entity, state in pairs:
        assert out.setdefault(entity, state) == state, (entity, state, out)
    return out


@pytest.mark.parametrize("case", sorted(EXPECTED))
def test_every_part_of_the_report_says_the_same_about_the_evidence(
    roots: dict[str, Path], case: str
) -> None:
    report = build_report(roots[case], cycle=CYCLE)
    html = report.html
    scene = _by_entity(
        re.findall(r'id="scene-entity-([\w.-]+?)-(resolved|broken|unresolved)"', html)
    )
    table = _by_entity(re.findall(r'data-entity="([^"]+)" data-evidence="(\w+)"', html))
    section = _by_entity(re.findall(r'data-external="([^"]+)" data-evidence="(\w+)"', html))
    assert scene == table == section == EXPECTED[case], (scene, table, section)
    # the page's metrics and the integrity verdict follow the same resolution
    metrics = report.data.metrics
    assert metrics.overall.unknown == (metrics.overall.decisions if case == "missing" else 0)
    assert report.data.integrity.ok == (case != "broken")
    chains = report.data.explanation.chains
    assert chains.unknown == (case == "missing")
    assert chains.fully_traceable == (case == "resolved")
    if case == "missing":
        assert "evidence FAILED" not in html and "front_bag not found" in html
        assert re.search(r"<th>ET</th>\s*<td>\?", html), "the decision's ET must read ?"


def test_the_time_row_and_axes_are_in_the_logs_clock(roots: dict[str, Path]) -> None:
    html = build_report(roots["resolved"], cycle=CYCLE).html
    assert "2026-05-04T09:01:30" in html
    assert not re.search(r"177788\d{4}\.\d", html), "a raw epoch time reached the page"
    assert "e9 -->" not in html, "an axis offset in epoch seconds reached a figure"


@pytest.mark.parametrize("fmt", ["dot", "mermaid"])
@pytest.mark.parametrize("case", sorted(EXPECTED))
def test_the_graph_exports_draw_missing_only_what_is_missing(
    roots: dict[str, Path], case: str, fmt: str
) -> None:
    text = export_decision(roots[case], cycle=CYCLE, fmt=fmt).text
    # broken: the cited scan is drawn MISSING; not read: UNKNOWN, never MISSING
    assert text.count("MISSING") == (1 if case == "broken" else 0), text
    assert text.count("UNKNOWN") == (1 if case == "missing" else 0), text


@pytest.mark.parametrize("fmt", ["dot", "mermaid"])
def test_export_takes_evidence_for_a_moved_recording(
    roots: dict[str, Path], fmt: str, tmp_path: Path
) -> None:
    moved = roots["resolved"].parent / "front_bag"
    done = runner.invoke(
        app,
        [
            "export",
            str(roots["missing"]),
            "--cycle",
            str(CYCLE),
            "--format",
            fmt,
            "--evidence",
            str(moved),
        ],
    )
    assert done.exit_code == 0, done.output
    assert "MISSING" not in done.stdout


@pytest.mark.parametrize("case", sorted(EXPECTED))
def test_foxglove_colours_an_entity_by_its_resolved_evidence(
    roots: dict[str, Path], case: str, tmp_path: Path
) -> None:
    pytest.importorskip("foxglove")
    from mcap.reader import make_reader

    out = tmp_path / "fox.mcap"
    done = runner.invoke(
        app,
        [
            "export",
            str(roots[case]),
            "--format",
            "foxglove",
            "--out",
            str(out),
            "--from",
            "+1.0",
            "--to",
            "+1.0",
        ],
    )
    assert done.exit_code == 0, done.output
    with out.open("rb") as f:
        scene = [m.data for _s, c, m in make_reader(f).iter_messages() if c.topic.endswith("scene")]
    text = b"".join(scene)
    person = {
        "resolved": b"person_1: person 0.90, evidence verified",
        "broken": b"person_1: person 0.90, evidence FAILED",
        "missing": b"person_1: person 0.90, evidence not checked",
    }[case]
    assert person in text, text
    assert b"cart_1: cart 0.90, evidence verified" in text
