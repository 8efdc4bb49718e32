"""The ``trace-audit`` typer app and the one place errors become exit codes.

Exit codes (documented in the README and in ``--help``):
  0 ok · 1 findings (verify failed, a metric under its threshold) · 2 usage (bad option,
  t outside the log, unknown action) · 3 unreadable input (missing, not MCAP, truncated,
  not a TRACE log, empty, a link or FIFO where a file belongs) · 4 cannot write (a read-only
  folder, a full disk).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import NoReturn, TypeVar

import typer

from trace_audit.cli.output import setup_logging
from trace_audit.cli.typer_compat import App, Group
from trace_runtime.errors import (
    EXIT_CANNOT_WRITE,
    EXIT_FINDINGS,
    EXIT_OK,
    EXIT_UNREADABLE,
    EXIT_USAGE,
    InputError,
    StorageError,
    TraceError,
    UsageError,
)

__all__ = [
    "EXIT_CANNOT_WRITE",
    "EXIT_FINDINGS",
    "EXIT_OK",
    "EXIT_UNREADABLE",
    "EXIT_USAGE",
    "app",
    "claim_process",
    "exit_code_for",
    "fail",
    "guarded",
    "help_text",
    "process_is_ours",
]

T = TypeVar("T")

_PROCESS = {"ours": False}
"""Whether this process runs one command and exits (``main``), so its process-wide limits are
ours to set; False when the app is called inside someone else's process (a test runner,
a script), whose children would inherit them."""


def claim_process() -> None:
    """Mark this process as the CLI's own (called by the console-script entry point)."""
    _PROCESS["ours"] = True


def process_is_ours() -> bool:
    return _PROCESS["ours"]


# The help is drawn by click's plain formatter (``rich_markup_mode=None``), not typer's rich
# panels: typer's rich help imports rich, markdown-it and pygments (~90 ms), which put every
# ``--help`` at 7x a bare interpreter against a budget of 4x (docs/performance.md, CLI start-up).
app = App(
    name="trace-audit",
    cls=Group,
    help=(
        "Investigate TRACE robot decision logs: explain a decision, find why the robot "
        "stopped, measure auditability, verify integrity, compact storage tiers.\n\n"
        "Exit codes: 0 ok, 1 findings, 2 usage error, 3 unreadable input, 4 cannot write."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    # As wide as the terminal up to 100 columns (click's default stops at 80); commands inherit it.
    context_settings={"max_content_width": 100},
)


def help_text(text: str) -> str:
    """Help with each prose paragraph on one line, so typer re-wraps it to the terminal;
    indented paragraphs (the examples) keep their lines."""
    return "\n\n".join(
        para if para.startswith("  ") else " ".join(line.strip() for line in para.splitlines())
        for para in text.strip().split("\n\n")
    )


def fail(message: str, code: int) -> NoReturn:
    """Print one line on stderr and exit with ``code``."""
    sys.stderr.write(f"trace-audit: {message}\n")
    raise typer.Exit(code)


_EXIT_CODES: tuple[tuple[type[TraceError], int], ...] = (
    (UsageError, EXIT_USAGE),
    (InputError, EXIT_UNREADABLE),
    (StorageError, EXIT_CANNOT_WRITE),
)
"""The error tree's three branches (trace_runtime/errors.py) and their exit codes."""


def exit_code_for(err: TraceError) -> int | None:
    """The documented exit code of an error raised by the library: the one place they are
    mapped. ``None`` for a ``TraceError`` outside the three branches: a bug, which
    ``guarded`` lets surface instead of calling it unreadable input."""
    for kind, code in _EXIT_CODES:
        if isinstance(err, kind):
            return code
    return None


def guarded(call: Callable[[], T]) -> T:
    """Run a library call; turn its ``TraceError`` into one stderr line and an exit code.

    Library warnings (a recovered segment, a skipped damaged chunk) go to stderr as one
    ``trace-audit: warning:`` line each, whichever command runs."""
    setup_logging()
    try:
        return call()
    except TraceError as err:
        code = exit_code_for(err)
        if code is None:
            raise
        fail(str(err), code)
    except KeyboardInterrupt:
        fail("interrupted", 130)
