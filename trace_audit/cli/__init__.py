"""The ``trace-audit`` command line: typer + rich live here and in the two program modules
(``sim/cli.py``, ``evaluation/cli.py``) only."""

from __future__ import annotations

import sys

import typer

from trace_audit.cli import (  # noqa: F401 - each module registers its commands
    assistant,
    check,
    comply,
    doctor,
    explain,
    export,
    fleet,
    info,
    integrity,
    keygen,
    metrics,
    proof,
    publish,
    report,
    storage,
    tail,
    timeline,
    why,
    witness,
)
from trace_audit.cli.app import EXIT_USAGE, app, claim_process
from trace_audit.cli.typer_compat import TyperException, help_without_command, usage_error_line

__all__ = ["app", "main"]

_SECTIONS = (
    ("Investigate", ("info", "explain", "why", "timeline", "tail", "export", "report", "mcp")),
    ("Measure and check rules", ("metrics", "check")),
    ("Integrity", ("verify", "keygen", "prove", "verify-proof", "publish", "witness")),
    ("Compliance", ("comply",)),
    ("Storage", ("compact", "catalog")),
    ("Fleet", ("index", "query", "find")),
    ("Authoring", ("doctor",)),
)
"""How ``trace-audit --help`` lists the commands: by what a user does with them, each
section's commands in this order (a sub-command group, ``witness``, after its section's
commands: click lists groups after commands)."""

_ORDER = [name for _title, names in _SECTIONS for name in names]
_SECTION_OF = {name: title for title, names in _SECTIONS for name in names}
app.registered_commands.sort(key=lambda command: _ORDER.index(command.name or ""))
for _info in app.registered_commands:
    _info.rich_help_panel = _SECTION_OF[_info.name or ""]
for _group in app.registered_groups:
    _group.rich_help_panel = _SECTION_OF[str(_group.name)]


def main() -> None:
    """Console-script entry point.

    Usage errors (an unknown option, a bad value) are one line on stderr with exit code 2,
    like every other error, instead of click's framed block."""
    claim_process()
    try:
        code = app.runner_for(sys.argv[1:])(standalone_mode=False)
    except TyperException as err:  # the command line's own errors: unknown option, bad value
        shown = help_without_command(err)  # `trace-audit`, `trace-audit witness`: the help
        if shown is not None:
            sys.stdout.write(shown)
        else:
            sys.stderr.write(usage_error_line(err, "trace-audit") or "")
        sys.exit(EXIT_USAGE)
    except typer.Abort:
        sys.stderr.write("trace-audit: interrupted\n")
        sys.exit(130)
    sys.exit(code if isinstance(code, int) else 0)
