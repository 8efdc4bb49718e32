"""``report --rules``: the safety rules judged over the report's window, as ``check`` judges
them over the same window, in their own section, the summary and the Reproduce commands."""

from __future__ import annotations

import json
import re
import shlex
from html import unescape
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from tests.trace_audit.incident_html import parse_report
from trace_audit.cli import app

REPO = Path(__file__).resolve().parents[3]
RULES = REPO / "docs" / "rules" / "warehouse.toml"
runner = CliRunner()


def _cli(*args: object) -> Any:
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def sim_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    import dataclasses

    import sim.decision
    from sim.faults import FaultRates
    from sim.policy import PolicyInput, evaluate
    from sim.runner import RunConfig, run

    def blind(inp: PolicyInput, values: Any) -> Any:  # a policy that ignores people past 1 m
        near = tuple(p for p in inp.peds if float(values[p[2]]) < 1.0)
        return evaluate(dataclasses.replace(inp, peds=near), values)

    out = tmp_path_factory.mktemp("sim") / "root"
    patch = pytest.MonkeyPatch()
    patch.setattr(sim.decision, "evaluate", blind)
    try:
        run(RunConfig(out=out, total_cycles=600, seed=1, faults=FaultRates.off()))
    finally:
        patch.undo()
    return out


def test_the_window_s_rules_are_checks_answer_over_it(sim_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "incident.html"
    done = _cli("report", sim_root, "--cycle", 300, "--rules", RULES, "--out", out, "--json")
    assert done.exit_code == 0, done.output
    summary = json.loads(done.stdout)
    assert "rules" in summary["sections"]
    html = out.read_text(encoding="utf-8")
    page = parse_report(html)
    assert page.section_ids == summary["sections"]

    (reproduce,) = [c for c in re.findall(r"<pre>(.*?)</pre>", html) if " check " in c]
    argv = shlex.split(unescape(reproduce))[1:]
    assert argv[:2] == ["check", str(sim_root)] and "--from" in argv and "--to" in argv
    checked = _cli(*argv, "--json")
    assert checked.exit_code == 1, checked.output  # the blind policy breaks rules here
    (robot,) = json.loads(checked.stdout)["robots"]
    assert summary["rules"] == [
        {
            "rule": r["rule"],
            "outcome": r["outcome"],
            "robustness": r["robustness"],
            "violations": len(r["violations"]),
        }
        for r in robot["rules"]
    ]
    violated = [r for r in robot["rules"] if r["violations"]]
    assert violated
    text = page.section_text["rules"]
    for rule in violated:
        assert rule["rule"] in text
        for v in rule["violations"]:
            assert v["explain"] in text


def test_without_rules_there_is_no_rules_section(sim_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "incident.html"
    done = _cli("report", sim_root, "--cycle", 300, "--out", out, "--json")
    summary = json.loads(done.stdout)
    assert summary["rules"] is None and "rules" not in summary["sections"]
    assert "rules" not in parse_report(out.read_text(encoding="utf-8")).section_ids


def test_a_bad_rules_file_is_exit_2_before_the_log_is_read(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[[rule]]\nname = "r"\nstl = "always(nearest.person <"\n')
    done = _cli("report", tmp_path / "missing", "--t", 1, "--rules", bad)
    assert done.exit_code == 2
    assert "rule 'r'" in done.stderr and "Traceback" not in done.stderr
