"""``trace-sim --help`` names values in words, as ``trace-audit --help`` does."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from evaluation.cli import app

COMMANDS = ["run", "scenarios", "baselines", "check-counterfactuals"]


def _help(*args: str) -> str:
    result = CliRunner().invoke(app, [*args, "--help"], prog_name="trace-sim")
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_options_show_no_python_type_names_markup_or_boxes(command: str | None) -> None:
    text = _help(*([command] if command else []))
    options = text.split("\nOptions:\n", 1)[1]
    assert not re.findall(r"<[a-z][^>]*>", options), options  # typer's "<int>", "<bool>"
    assert "[bold]" not in text and "╭" not in text, text


def test_values_are_named_as_click_and_trace_audit_name_them() -> None:
    run = _help("run")
    assert re.search(r"-o, --out PATH\s", run) and re.search(r"--cycles INTEGER\s", run)
    assert re.search(r"--duration TEXT\s", run) and re.search(r"--faults on\|off\s", run)
    assert re.search(r"--json\s+print the summary as JSON", run)  # a flag takes no value
    assert "Needs the [baselines] extra" in " ".join(_help("baselines").split())


def test_the_command_list_shows_each_whole_summary() -> None:
    listed = " ".join(_help().split("\nCommands:\n", 1)[1].split())
    assert (
        "run Simulate scenarios and write the TRACE log plus a fault ground-truth sidecar."
        in listed
    )
    assert "..." not in listed
