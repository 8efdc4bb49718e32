"""The CLI starts light: what ``trace-audit`` imports before a command needs the library.

Start-up time is a budget (DESIGN.md: ``--help`` within 4x a bare ``python -c pass``;
bench/bench_cli.py measures it). Timing is not asserted here, on a shared machine it would
flake; what these tests pin is the cause of a slow start: a heavy module imported by a
process that does not use it.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from trace_audit.cli import app

ALL_COMMANDS = (
    *(c.name or "" for c in app.registered_commands),
    *(str(g.name) for g in app.registered_groups),
    *(
        f"{g.name} {c.name}"
        for g in app.registered_groups
        if g.typer_instance is not None
        for c in g.typer_instance.registered_commands
    ),
)
"""Every command line that has a ``--help``: commands, sub-command groups and their commands."""

# The library behind the commands: pydantic record models, the MCAP reader, graphs, arrays.
HEAVY = ("pydantic", "networkx", "numpy", "mcap", "trace_runtime.records", "trace_audit.metrics")


def _loaded_after(code: str) -> set[str]:
    script = f"import sys\n{code}\nprint(' '.join(sorted(sys.modules)))\n"
    out = subprocess.run(
        [sys.executable, "-c", script], check=True, capture_output=True, text=True, timeout=60
    )
    return set(out.stdout.split())


def test_importing_the_cli_imports_no_library_and_no_rich() -> None:
    loaded = _loaded_after("import trace_audit.cli")
    assert not loaded & {*HEAVY, "rich"}


@pytest.mark.parametrize("command", ["", *ALL_COMMANDS])
def test_help_imports_no_library(command: str) -> None:
    """Every command's ``--help`` too, not only the top-level one (typer coerces the
    group's unset ``--help`` flag with pydantic unless it starts as ``False``)."""
    argv = ["trace-audit", *command.split(), "--help"]
    code = (
        "from trace_audit.cli import main\n"
        f"sys.argv = {argv!r}\n"
        "try:\n"
        "    main()\n"
        "except SystemExit as exit:\n"
        "    assert exit.code == 0, exit.code\n"
        "sys.stdout.flush()\n"
        "sys.stdout = sys.__stderr__\n"
    )
    script = f"import sys\n{code}\nprint(' '.join(sorted(sys.modules)))\n"
    out = subprocess.run(
        [sys.executable, "-c", script], check=True, capture_output=True, text=True, timeout=60
    )
    loaded = set(out.stderr.split())
    assert "Usage" in out.stdout
    # rich too: typer's rich help imports rich, markdown-it and pygments (~90 ms)
    assert not loaded & {*HEAVY, "rich"}
    # the help is drawn plain, so rich markup in a help text must not show up as tags
    assert "[bold]" not in out.stdout
    assert "[/" not in out.stdout
    # arguments in the usage line as LOG, not typer's "{log}"
    usage = out.stdout.splitlines()[0]
    assert "{" not in usage
    arguments = usage.partition("[OPTIONS]")[2].split()
    assert all(a.strip("[].") == a.strip("[].").upper() for a in arguments), usage


def test_a_command_registered_the_usual_way_gets_the_plain_help() -> None:
    """A new command module needs nothing beyond ``@app.command(...)``: its help loses
    its rich markup and the command list shows its whole first paragraph."""
    from typer.testing import CliRunner

    from trace_audit.cli.typer_compat import App, Group

    demo = App(cls=Group, rich_markup_mode=None, add_completion=False)
    long = "Write a [bold]long[/bold] first paragraph that click would otherwise cut short."

    @demo.command("report", help=f"{long}\n\n[bold]Examples[/bold]:\n\n  demo report x")
    def report() -> None: ...

    @demo.command("other", help="Another command.")
    def other() -> None: ...

    runner = CliRunner()
    top = runner.invoke(demo, ["--help"], terminal_width=200)
    assert long.replace("[bold]", "").replace("[/bold]", "") in top.output
    sub = runner.invoke(demo, ["report", "--help"])
    assert "Examples:" in sub.output
    assert "[bold]" not in sub.output


def test_compact_help_defaults_are_the_librarys() -> None:
    """``compact --help`` shows its defaults without importing the compaction machinery;
    they must stay the library's."""
    from trace_audit.cli import storage
    from trace_runtime.tiers import DEFAULT_RETENTION_NS, ColdOptions

    shown = (storage._DEFAULT_RETENTION, storage._DEFAULT_BLOCK_CYCLES)
    assert shown == (f"{DEFAULT_RETENTION_NS // 86_400_000_000_000}d", ColdOptions().block_cycles)


def test_help_names_values_as_click_does_not_by_python_type() -> None:
    """ "--evidence PATH" and "LOGS...", not typer's "--evidence <list[Path]>"."""
    from typer.testing import CliRunner

    from trace_audit.cli import app

    shown = CliRunner().invoke(app, ["metrics", "--help"]).output
    assert "--evidence PATH" in shown and "--jobs INTEGER" in shown
    assert "--gap-tolerance NUMBER" in shown and "--end TIME" in shown
    assert "\n  LOGS...  " in shown
    assert "<" not in shown.split("Arguments:")[1].replace("<=", "")


_DEMO = """
import sys
from pathlib import Path
from typing import Annotated, Optional
import typer
from trace_audit.cli.typer_compat import App, Group

demo = App(cls=Group, rich_markup_mode=None, add_completion=False)

@demo.command("q")
def q(
    index: Path,
    sql: str,
    limit: Annotated[Optional[int], typer.Option("--limit", min=0)] = None,
    robot: Annotated[Optional[list[str]], typer.Option("--robot")] = None,
    logs: Annotated[Optional[list[Path]], typer.Option("--log")] = None,
) -> None:
    print(repr(index), repr(sql), repr(limit), repr(robot), repr(logs))

@demo.command("other")
def other() -> None: ...

try:
    demo(sys.argv[1:], standalone_mode=False)
except typer.BadParameter as err:
    print("bad:", err.format_message())
print("pydantic" in sys.modules)
"""


def _demo(*args: str) -> list[str]:
    done = subprocess.run(
        [sys.executable, "-c", _DEMO, *args], check=True, capture_output=True, text=True
    )
    return done.stdout.splitlines()


def test_text_and_paths_reach_a_command_without_pydantic() -> None:
    """typer 0.29 would build a pydantic adapter for every parameter (~70 ms a command):
    text and paths are given as typer gives them, and pydantic is never imported."""
    assert _demo("q", "idx", "SELECT 1", "--robot", "a", "--robot", "b", "--log", "x") == [
        "PosixPath('idx') 'SELECT 1' None ['a', 'b'] [PosixPath('x')]",
        "False",
    ]


def test_a_number_is_still_typers_with_its_checks_and_messages() -> None:
    assert _demo("q", "idx", "s", "--limit", "5")[0] == "PosixPath('idx') 's' 5 None None"
    refused = _demo("q", "idx", "s", "--limit", "-1")
    assert refused[0].startswith("bad:") and "0" in refused[0], refused
