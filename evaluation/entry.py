"""The ``trace-sim`` console script's first step: the simulator's commands need the
investigator's extra (typer, rich and numpy), so a robot's install (``pip install .``) gets one
line naming the ``cli`` extra instead of a traceback (``trace_audit.entry``)."""

from __future__ import annotations

from trace_audit.entry import require

__all__ = ["main"]


def main() -> None:
    """Entry point of ``trace-sim``: the check, then the program."""
    require("trace-sim")
    from evaluation.cli import main as cli_main

    cli_main()
