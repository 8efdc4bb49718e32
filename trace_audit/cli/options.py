"""The options and arguments more than one command takes, each defined once.

An option shared with the same words is an ``Annotated`` alias (``JsonOption``); one whose
help names what it does for the command at hand is made by a function (``cycle_option``,
``evidence_option``), so the flag, its type and its settings still live here alone. A
command's own options stay beside the command.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.fleet.limits import QueryLimits, format_size

if TYPE_CHECKING:
    from concurrent.futures import Executor

    from trace_audit.cli.typer_compat import OptionInfo

__all__ = [
    "CheckedLogArgument",
    "CsvOption",
    "EvidenceOption",
    "EvidencePaths",
    "FromOption",
    "IndexArgument",
    "JsonOption",
    "LogArgument",
    "MemoryLimitOption",
    "PlainOption",
    "RobotsOption",
    "RootArgument",
    "SchedulerOption",
    "SqlTimeoutOption",
    "TimeOption",
    "ToOption",
    "action_option",
    "cluster",
    "cycle_option",
    "evidence_option",
    "jobs_option",
    "key_option",
    "limit_option",
    "robot_option",
    "sql_limits",
]

# --- output ----------------------------------------------------------------------------------

JsonOption = Annotated[bool, typer.Option("--json", help="Print machine-readable JSON on stdout.")]
PlainOption = Annotated[
    bool, typer.Option("--plain", help="No colour or box drawing (for logs and CI).")
]
CsvOption = Annotated[bool, typer.Option("--csv", help="Print CSV on stdout.")]

# --- what is read ----------------------------------------------------------------------------

LogArgument = Annotated[
    Path,
    typer.Argument(
        help="A TRACE segment (.mcap), a directory of segments, or a log root (hot/ warm/ cold/).",
        show_default=False,
    ),
]
"""The log an investigating command reads."""

CheckedLogArgument = Annotated[
    Path,
    typer.Argument(
        help="A TRACE segment (.mcap), a directory of segments, or a log root.",
        show_default=False,
    ),
]
"""The log a checking command (verify, doctor) reads."""

RootArgument = Annotated[Path, typer.Argument(help="A log root (with hot/ warm/ cold/).")]
IndexArgument = Annotated[Path, typer.Argument(help="The index directory.", show_default=False)]

EvidencePaths = list[Path] | None
"""External recordings (``--evidence``), as typer hands them over."""

# The option factories below bind ``typer.Option(...)`` to an ``OptionInfo``: typer annotates
# it ``-> Any`` so that it may stand as a parameter's default, and returns an ``OptionInfo``.


def evidence_option(
    named_by: str = "the log's evidence refs", then: str = "; repeat for several."
) -> OptionInfo:
    """``--evidence``: the external recordings that evidence refs (``named_by``) name."""
    option: OptionInfo = typer.Option(
        "--evidence",
        help=f"An external recording (MCAP file or rosbag2 directory) {named_by} name{then}",
        show_default=False,
    )
    return option


EvidenceOption = Annotated[EvidencePaths, evidence_option()]

# --- which decision --------------------------------------------------------------------------

TimeOption = Annotated[
    str | None,
    typer.Option(
        "--t",
        help="Seconds in the log's clock (12.3), seconds after the log start (+12.3), or on a "
        "wall clock an ISO 8601 time (2026-05-04T06:04:25Z).",
        show_default=False,
    ),
]


def cycle_option(verb: str) -> OptionInfo:
    """``--cycle N``, the other way to name a decision than ``--t``: "``verb`` this cycle"."""
    option: OptionInfo = typer.Option(
        "--cycle", help=f"{verb} this cycle number instead of a time.", show_default=False
    )
    return option


def action_option(help: str) -> OptionInfo:
    """``--action``: a command the robot logged, e.g. STOP."""
    option: OptionInfo = typer.Option("--action", help=help, show_default=False)
    return option


FromOption = Annotated[
    str | None,
    typer.Option(
        "--from",
        help="Start of the window (seconds, +seconds after the log start, or on a wall "
        "clock an ISO 8601 time). Default: the log start.",
        show_default=False,
    ),
]
"""``--from``: the start of the window a command reads (``selection``, ``log_time``)."""
ToOption = Annotated[
    str | None,
    typer.Option(
        "--to", help="End of the window (same forms). Default: the log end.", show_default=False
    ),
]
"""``--to``: the end of that window."""

RobotsOption = Annotated[
    list[str] | None,
    typer.Option(
        "--robot",
        help="Only this robot's decisions (repeat for several).",
        show_default=False,
    ),
]
"""``--robot``, repeatable: the robots an investigating command reads (``selection``)."""


def robot_option(help: str) -> OptionInfo:
    """``--robot``: one robot of a fleet."""
    option: OptionInfo = typer.Option("--robot", help=help, show_default=False)
    return option


def limit_option(help: str, *, least: int) -> OptionInfo:
    """``--limit``: at most this many rows."""
    option: OptionInfo = typer.Option("--limit", help=help, min=least)
    return option


# --- how it runs -----------------------------------------------------------------------------


def jobs_option(help: str) -> OptionInfo:
    """``--jobs`` / ``-j``: local processes."""
    option: OptionInfo = typer.Option("--jobs", "-j", help=help, min=1)
    return option


SchedulerOption = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="Run on the Dask cluster at this address (tcp://host:8786); workers must see "
        "the same paths (shared storage). Default: local processes.",
        show_default=False,
    ),
]


@contextlib.contextmanager
def cluster(address: str | None) -> Iterator[Executor | None]:
    """The Dask cluster's executor for ``--scheduler``, or None (local processes)."""
    if address is None:
        yield None
        return
    from trace_audit.fleet.cluster import dask_executor

    with dask_executor(address) as executor:
        yield executor


_SQL_DEFAULTS = QueryLimits()

MemoryLimitOption = Annotated[
    str | None,
    typer.Option(
        "--memory-limit",
        help="Memory the SQL may use, e.g. 4GB or 512MiB (DuckDB's memory_limit; the "
        f"process is capped at twice it). Default: {format_size(_SQL_DEFAULTS.memory_bytes)}.",
        show_default=False,
    ),
]
SqlTimeoutOption = Annotated[
    float | None,
    typer.Option(
        "--timeout",
        help=f"Seconds the SQL may run before it is stopped. Default: {_SQL_DEFAULTS.timeout_s:g}.",
        show_default=False,
    ),
]


def sql_limits(memory_limit: str | None, timeout: float | None) -> QueryLimits:
    """The bounds ``--memory-limit`` and ``--timeout`` give, with this process capped to
    them when it is the CLI's own (``app.process_is_ours``; ``limits.cap_process_memory``):
    never the process of a caller who runs the app inside theirs, whose later children
    (a browser) would inherit the cap."""
    from trace_audit.cli.app import process_is_ours
    from trace_audit.fleet.limits import cap_process_memory, parse_size

    limits = QueryLimits(
        memory_bytes=_SQL_DEFAULTS.memory_bytes
        if memory_limit is None
        else parse_size(memory_limit),
        timeout_s=_SQL_DEFAULTS.timeout_s if timeout is None else timeout,
    )
    if process_is_ours():
        cap_process_memory(limits)
    return limits


def key_option(help: str) -> OptionInfo:
    """``--key``: the robots' Ed25519 public key."""
    option: OptionInfo = typer.Option("--key", help=help, show_default=False)
    return option
