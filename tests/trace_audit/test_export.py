"""export: the causal graph and counterfactual tree as DOT, Mermaid and JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import t_ns
from trace_audit.cli import app
from trace_audit.export import export_decision
from trace_runtime.errors import UsageError


def test_json_holds_both_graphs(sample_log: Path) -> None:
    out = export_decision(sample_log, t=t_ns(45), fmt="json")
    data = json.loads(out.text)
    assert (data["cycle"], data["command"]) == (45, "STOP")
    ids = {n["id"] for n in data["causal_graph"]["nodes"]}
    assert {"action", "entity:ped_1", "belief:collision_risk"} <= ids
    assert data["decision_tree"]["graph"]["taken_path"] == ["root", "ped", "stop"]
    assert out.undocumented == 0 and out.nodes == len(ids)


def test_dot_marks_the_taken_path_and_missing_links(sample_log: Path) -> None:
    good = export_decision(sample_log, t=t_ns(45), fmt="dot").text
    assert good.startswith("digraph trace_decision {") and good.rstrip().endswith("}")
    assert good.count("penwidth=2.5") == 2  # root -> ped -> stop
    assert "MISSING" not in good
    broken = export_decision(sample_log, t=t_ns(82), fmt="dot")
    assert broken.undocumented == 2
    assert broken.text.count('label="MISSING ') == 2
    assert "style=dashed, color=red" in broken.text


def test_mermaid_flowchart(sample_log: Path) -> None:
    text = export_decision(sample_log, t=t_ns(82), fmt="mermaid").text
    assert text.startswith("flowchart BT")
    assert text.count("==>") == 2 and text.count("-.->") == 2
    assert "linkStyle" in text and "class " in text


def test_unknown_format(sample_log: Path) -> None:
    with pytest.raises(UsageError, match="unknown export format"):
        export_decision(sample_log, t=t_ns(45), fmt="svg")


def test_cli_writes_the_file(sample_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "stop.dot"
    result = CliRunner().invoke(
        app, ["export", str(sample_log), "--t", "+4.5", "--format", "dot", "--out", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert out.read_text().startswith("digraph") and "wrote" in result.stderr
    bad = CliRunner().invoke(app, ["export", str(sample_log), "--t", "+4.5", "--format", "svg"])
    assert bad.exit_code == 2 and "unknown export format" in bad.stderr


def test_exports_never_overwrite_and_reports_follow_no_link(
    sample_log: Path, tmp_path: Path
) -> None:
    """The README: exit 4 for "an export's output that exists: exports never overwrite".
    The incident report refreshes its page, but through a fresh sibling: a link at --out
    is refused, and one planted where it used to write its partial (``.NAME.partial``) is
    not followed; what either points at is left as it was."""
    keep = tmp_path / "keep.txt"
    keep.write_text("keep")
    existing = tmp_path / "stop.dot"
    existing.write_text("mine")
    runner = CliRunner()
    again = runner.invoke(
        app, ["export", str(sample_log), "--t", "+4.5", "--format", "dot", "--out", str(existing)]
    )
    assert again.exit_code == 4 and "never overwritten" in again.stderr
    assert existing.read_text() == "mine"
    fresh = tmp_path / "fresh.html"
    (tmp_path / ".fresh.html.partial").symlink_to(keep)
    made = runner.invoke(app, ["report", str(sample_log), "--t", "+4.5", "--out", str(fresh)])
    assert made.exit_code == 0, made.output
    assert fresh.read_text().startswith("<!DOCTYPE html") and keep.read_text() == "keep"
    linked = tmp_path / "linked.html"
    linked.symlink_to(keep)
    refused = runner.invoke(app, ["report", str(sample_log), "--t", "+4.5", "--out", str(linked)])
    assert refused.exit_code in (3, 4) and keep.read_text() == "keep", refused.output
    assert refused.stderr.count("\n") == 1 and "Traceback" not in refused.output
