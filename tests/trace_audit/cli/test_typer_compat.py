"""``trace-audit COMMAND ...`` runs a group holding that command alone (``App.runner_for``):
typer would otherwise build all fifteen commands first. What it prints must not change."""

from __future__ import annotations

from typing import Any

import pytest
from typer.main import get_command

from trace_audit.cli import app

ALL_COMMANDS = tuple(c.name or "" for c in app.registered_commands)


def _run(runner: Any, args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[str, str]:
    """What a command line prints (its help), or the error it stops with and where."""
    try:
        runner.main(args, prog_name="trace-audit", standalone_mode=False)
    except Exception as err:  # a usage error: its text and the command it names
        ctx = getattr(err, "ctx", None)
        return type(err).__name__, f"{ctx.command_path if ctx else ''}: {err}"
    return "ok", capsys.readouterr().out


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_a_command_alone_prints_what_it_prints_among_all(
    command: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "100")
    whole = get_command(app)
    alone = app.runner_for([command, "--help"])
    assert alone is not app and list(alone.commands) == [command]  # type: ignore[attr-defined]
    for args in ([command, "--help"], [command, "--no-such-option"]):
        assert _run(alone, args, capsys) == _run(whole, args, capsys)


@pytest.mark.parametrize(
    "args",
    [
        ["witness", "--help"],
        ["witness", "serve", "--help"],
        ["witness", "vkey", "--listen", "x"],
        ["witness", "dance"],
        ["witness"],
    ],
)
def test_a_sub_command_group_alone_prints_what_it_prints_among_all(
    args: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "100")
    alone = app.runner_for(args)
    assert alone is not app and list(alone.commands) == ["witness"]  # type: ignore[attr-defined]
    assert _run(alone, args, capsys) == _run(get_command(app), args, capsys)


@pytest.mark.parametrize("args", [["explian", "LOG"], ["--json"], ["EXPLAIN"], ["-h", "explain"]])
def test_anything_but_a_command_name_first_meets_the_whole_app(args: list[str]) -> None:
    assert app.runner_for(args) is app


@pytest.mark.parametrize("args", [[], ["--help"]])
def test_the_command_list_is_the_whole_apps_without_building_parameters(
    args: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The top-level help lists names and help only: it is drawn from stand-ins without
    parameters (building every command's was most of its time), and prints the same."""
    monkeypatch.setenv("COLUMNS", "100")
    listing = app.runner_for(args)
    assert listing is not app
    assert all(not c.params for c in listing.commands.values())  # type: ignore[attr-defined]
    whole = get_command(app)
    assert _run(listing, args or ["--help"], capsys) == _run(whole, args or ["--help"], capsys)


def test_the_app_keeps_all_its_commands() -> None:
    app.runner_for(["explain"])
    assert tuple(c.name for c in app.registered_commands) == ALL_COMMANDS
    assert len(ALL_COMMANDS) > 1


def test_the_command_list_is_grouped_by_what_a_user_does(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``trace-audit --help`` lists every command once, under section headings at the margin
    (investigating first, authoring last), with the names aligned across sections."""
    monkeypatch.setenv("COLUMNS", "100")
    status, shown = _run(app.runner_for(["--help"]), ["--help"], capsys)
    assert status == "ok"
    listed = shown.split("\nCommands:\n\n", 1)[1]
    headings = [line[:-1] for line in listed.splitlines() if line and not line.startswith(" ")]
    assert headings == [
        "Investigate", "Measure and check rules", "Integrity", "Compliance", "Storage",
        "Fleet", "Authoring",
    ]  # fmt: skip
    rows = [line for line in listed.splitlines() if line.startswith("  ") and line[2] != " "]
    names = [row.split()[0] for row in rows]
    assert names[:2] == ["info", "explain"] and names[-1] == "doctor"
    everything = [*ALL_COMMANDS, *(str(g.name) for g in app.registered_groups)]
    assert sorted(names) == sorted(everything)
    assert len({row.index(row.split()[1], len(row.split()[0]) + 2) for row in rows}) == 1
