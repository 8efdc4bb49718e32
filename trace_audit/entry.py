"""The ``trace-audit`` console script's first step: is the investigator installed here?

A robot's install (``pip install .``, no extras) carries ``trace_runtime`` and its light
dependencies only; typer, rich, networkx and numpy come with the ``cli`` extra. Without them
``trace-audit`` and ``trace-sim`` say so in one line on stderr and exit with
``EXIT_NOT_INSTALLED`` (docs/cli.md), instead of a ``ModuleNotFoundError`` traceback. This
module imports nothing beyond the standard library and ``trace_runtime.errors`` (where every
program's exit codes are numbered) until the check has passed.
"""

from __future__ import annotations

import sys
from importlib.util import find_spec

from trace_runtime.errors import EXIT_NOT_INSTALLED

__all__ = ["INVESTIGATOR_MODULES", "main", "missing_modules", "require"]

INVESTIGATOR_MODULES = ("typer", "rich", "networkx", "numpy")
"""What the ``cli`` extra brings, by import name (tests/test_install.py holds this to
pyproject.toml's ``cli`` extra)."""


def missing_modules() -> list[str]:
    """The investigator's modules this environment lacks, found without importing any."""
    return [name for name in INVESTIGATOR_MODULES if find_spec(name) is None]


def require(prog: str) -> None:
    """Exit with one line naming the ``cli`` extra when the investigator is not installed."""
    missing = missing_modules()
    if missing:
        sys.stderr.write(
            f"{prog}: the investigator is not installed in this environment"
            f" (no {', '.join(missing)}): pip install 'trace-audit[cli]'"
            " (from a checkout: pip install '.[cli]')\n"
        )
        sys.exit(EXIT_NOT_INSTALLED)


def main() -> None:
    """Entry point of ``trace-audit``: the check, then the CLI."""
    require("trace-audit")
    from trace_audit.cli import main as cli_main

    cli_main()
