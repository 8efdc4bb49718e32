"""The examples in ``--help`` run as written: each is one shell line that bash parses, not a
command with a remark in parentheses or one the formatter wrapped at 80 columns (review F9).

Covers every ``trace-audit`` and ``trace-sim`` command, and each command of a sub-command
group (``witness serve``).
"""

from __future__ import annotations

import shutil
import subprocess

import pytest
import typer
from typer.testing import CliRunner

from evaluation.cli import app as sim_app
from trace_audit.cli import app as audit_app


def _group_commands(app: typer.Typer) -> list[str]:
    """Each sub-command group (``witness``) and each of its commands (``witness serve``)."""
    names = []
    for group in app.registered_groups:
        assert group.typer_instance is not None and isinstance(group.name, str)
        names.append(group.name)
        names += [f"{group.name} {c.name}" for c in group.typer_instance.registered_commands]
    return names


CASES = [
    *((audit_app, "trace-audit", c.name or "") for c in audit_app.registered_commands),
    *((audit_app, "trace-audit", name) for name in _group_commands(audit_app)),
    (sim_app, "trace-sim", "run"),
    (sim_app, "trace-sim", "baselines"),
    (sim_app, "trace-sim", "check-counterfactuals"),
]


def _examples(app: typer.Typer, prog: str, command: str) -> list[tuple[str, str]]:
    """(example line, the line after it) as help prints them on an 80-column terminal."""
    shown = CliRunner().invoke(app, [*command.split(), "--help"], prog_name=prog, terminal_width=80)
    assert shown.exit_code == 0, shown.output
    lines = [*shown.stdout.splitlines(), ""]
    return [
        (line.strip(), lines[i + 1])
        for i, line in enumerate(lines)
        if line.startswith(f"    {prog} ")
    ]


@pytest.mark.skipif(shutil.which("bash") is None, reason="needs bash to parse the examples")
@pytest.mark.parametrize(("app", "prog", "command"), CASES)
def test_each_example_is_one_line_bash_parses(app: typer.Typer, prog: str, command: str) -> None:
    examples = _examples(app, prog, command)
    assert examples, f"{prog} {command} --help shows no example"
    for example, after in examples:
        assert not after.strip(), f"wrapped: {example!r} / {after.strip()!r}"
        parsed = subprocess.run(
            ["bash", "-n", "-c", example], check=False, capture_output=True, text=True
        )
        assert parsed.returncode == 0, f"{example!r}: {parsed.stderr}"
