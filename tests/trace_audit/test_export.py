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
