"""The ``trace-audit`` command line: typer + rich live here and in ``sim/cli.py`` only."""

from __future__ import annotations

import sys

import typer
from typer.exceptions import TyperException

from trace_audit.cli import (  # noqa: F401 - each module registers its commands
    doctor,
    fleet,
    integrity,
    investigate,
    metrics,
    report,
    storage,
)
from trace_audit.cli.app import EXIT_USAGE, app

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point.

    Usage errors (an unknown option, a bad value) are one line on stderr with exit code 2,
    like every other error, instead of click's framed block."""
    try:
        code = app.runner_for(sys.argv[1:])(standalone_mode=False)
    except TyperException as err:  # the command line's own errors: unknown option, bad value
        ctx = getattr(err, "ctx", None)
        command = ctx.command_path if ctx is not None else "trace-audit"
        message = err.format_message() if hasattr(err, "format_message") else str(err)
        if message.strip():  # (no arguments at all: the help was shown instead)
            sys.stderr.write(f"trace-audit: {message} (see '{command} --help')\n")
        sys.exit(EXIT_USAGE)
    except typer.Abort:
        sys.stderr.write("trace-audit: interrupted\n")
        sys.exit(130)
    sys.exit(code if isinstance(code, int) else 0)
