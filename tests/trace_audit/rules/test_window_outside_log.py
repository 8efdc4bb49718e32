"""Bugs an outside user found in check: one-cycle stretches, prev/next on numbers, JSON
infinities, windows outside the log, and error messages."""

from __future__ import annotations

from pathlib import Path

import pytest
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


@pytest.mark.parametrize(("start", "end"), [("300", None), ("140", "130"), (None, "10")])
def test_a_window_outside_the_log_exits_2_naming_its_range(
    tmp_path: Path, sample_log: Path, start: str | None, end: str | None
) -> None:
    rules = _file(tmp_path, _rules("stop", "always(command.STOP < 0.5)"))
    args = [str(sample_log), "--rules", rules, "--plain"]
    args += ["--from", start] if start else []
    args += ["--to", end] if end else []
    code, out, err = _run(*args)
    assert code == 2, (out, err)
    assert "the log's range" in err and len(err.strip().splitlines()) == 1
