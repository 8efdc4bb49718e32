"""The ``trace-audit`` command line: typer + rich live here and in ``sim/cli.py`` only."""

from __future__ import annotations

from trace_audit.cli import integrity, investigate, metrics, storage  # noqa: F401 - register
from trace_audit.cli.app import app

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point."""
    app()
