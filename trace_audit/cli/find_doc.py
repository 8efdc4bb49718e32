"""``find`` for people: one row per run of found decisions (``fleet.find.found_runs``),
times in the robot's own clock; ``--json`` and ``--csv`` keep one row per cycle."""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_audit.cli.doc import Column, Doc

if TYPE_CHECKING:
    from trace_audit.fleet.find import FoundRun
    from trace_audit.fleet.query import QueryResult

__all__ = ["found_doc"]


def found_doc(result: QueryResult) -> Doc:
    """The found decisions as runs: robot, when, cycles, how many, the command (and the one
    before it), the lead factor, the closest entity, the lowest ET, and the explain command
    of the run's first cycle."""
    from trace_audit.fleet.find import found_runs

    runs = found_runs(result)
    near = "nearest_m" in result.columns
    doc = Doc()
    doc.table(
        [
            Column("robot"),
            Column("when"),
            Column("cycles"),
            Column("n", "right"),
            Column("command"),
            Column("lead factor"),
            *((Column("nearest"),) if near else ()),
            Column("ET", "right"),
            Column("explain (first cycle)"),
        ],
        ([*_cells(run, near)] for run in runs),
    )
    shown = sum(run.decisions for run in runs)
    counted = (
        f"{shown} of {result.total} decisions (--limit {len(result.rows)})"
        if result.total is not None
        else f"{shown} decisions"
    )
    doc.line(
        f"{counted} in {len(runs)} run{'s' if len(runs) != 1 else ''}, "
        f"in {result.elapsed_s * 1000:.0f} ms; --json gives each cycle"
    )
    return doc


def _cells(run: FoundRun, near: bool) -> list[str]:
    first = run.first
    span = _time(run.first_ns, run.wall)
    if run.last_ns != run.first_ns:
        span += f" .. {_time(run.last_ns, run.wall)}"
    cycles = str(run.first_cycle)
    if run.last_cycle != run.first_cycle:
        cycles += f"-{run.last_cycle}"
    command = str(run.command or "-")
    if run.previous_command and run.previous_command != run.command:
        command += f" (after {run.previous_command})"
    lead = _lead(first)
    closest = (
        [f"{first.get('nearest_class') or '?'} {run.nearest_m:g} m"]
        if near and run.nearest_m is not None
        else (["-"] if near else [])
    )
    et = "?" if run.et_lowest is None else f"{run.et_lowest:.2f}"
    return [
        run.robot,
        span,
        cycles,
        str(run.decisions),
        command,
        lead,
        *closest,
        et,
        str(first.get("explain") or "-"),
    ]


def _lead(first: dict[str, object]) -> str:
    name = first.get("lead_factor")
    if not name:
        return "-"
    value, unit = first.get("lead_value"), first.get("lead_unit")
    shown = f"{value:g}" if isinstance(value, float) else str(value or "")
    return f"{name} {shown}{' ' + str(unit) if unit else ''}".strip()


def _time(t_ns: int, wall: bool) -> str:
    """A time in the robot's own clock: ISO UTC on a wall clock, else seconds."""
    from trace_runtime.clock import iso_utc

    return iso_utc(t_ns, digits=3) if wall else f"{t_ns / 1e9:.3f} s"
