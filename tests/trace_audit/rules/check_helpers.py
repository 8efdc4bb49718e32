"""What the rules tests share: a rules file's text, a rules file on disk, and
``trace-audit check`` run in this process."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from trace_audit.cli import app


def rule_text(name: str, stl: str) -> str:
    """One ``[[rule]]`` of a rules file."""
    return f'[[rule]]\nname = "{name}"\nstl = "{stl}"\n'


def rules_file(tmp_path: Path, text: str) -> str:
    """``text`` written as ``tmp_path/rules.toml``; its path, as the CLI takes it."""
    path = tmp_path / "rules.toml"
    path.write_text(text)
    return str(path)


def run_check(*args: str) -> tuple[int, str, str]:
    """``trace-audit check ARGS``: exit code, stdout, stderr."""
    result = CliRunner().invoke(app, ["check", *args])
    return result.exit_code, result.stdout, result.stderr
