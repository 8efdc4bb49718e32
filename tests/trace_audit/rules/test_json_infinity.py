"""Bugs an outside user found in check: one-cycle stretches, prev/next on numbers, JSON
infinities, windows outside the log, and error messages."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from trace_audit.cli import app

PERIOD_NS = 100_000_000


def _rules(name: str, stl: str) -> str:
    return f'[[rule]]\nname = "{name}"\nstl = "{stl}"\n'


def _run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(app, ["check", *args])
    return result.exit_code, result.stdout, result.stderr


def _file(tmp_path: Path, text: str) -> str:
    path = tmp_path / "rules.toml"
    path.write_text(text)
    return str(path)


def test_an_infinite_robustness_is_null_in_json(tmp_path: Path, sample_log: Path) -> None:
    rules = _file(tmp_path, _rules("far", "always(nearest.vehicle > 1.0)"))
    code, out, _ = _run(str(sample_log), "--rules", rules, "--json")
    assert code == 0 and "Infinity" not in out
    (rule,) = json.loads(out)["robots"][0]["rules"]
    assert rule["robustness"] is None and rule["outcome"] == "satisfied"
    code, out, _ = _run(str(sample_log), "--rules", rules, "--plain")
    assert code == 0 and "robustness inf" in out
