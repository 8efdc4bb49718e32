"""``trace-audit timeline``: the decisions over time, a row per change, and the gaps.

Parses its arguments, calls ``trace_audit.transitions.timeline`` and renders the typed result:
rich on a terminal, plain text with ``--plain`` or in a pipe, JSON with ``--json``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Line, Seg, fmt_duration, fmt_t, fmt_value
from trace_audit.cli.options import (
    FromOption,
    JsonOption,
    LogArgument,
    PlainOption,
    RobotsOption,
    ToOption,
)
from trace_audit.cli.output import emit_per_robot

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from collections.abc import Sequence
    from pathlib import Path

    from trace_audit.transitions import ClockRun, Timeline, TimelineRow
    from trace_runtime.gaps import Gap

__all__ = ["timeline_command", "timeline_doc", "timeline_each_robot"]

_TIMELINE_HELP = """The decisions over time: a row per decision change, with the leading
factor and execution flags, and the gaps where no cycle was logged.

Each row is a stretch of cycles with one command: when it began, how long it held, the
leading factor (the first the rationale names) and the flags raised while it held.
--every gives a row per cycle instead. In a root of several robots each robot's timeline
is shown under its name (--robot selects robots).

[bold]Examples[/bold]:

  trace-audit timeline run.mcap

  trace-audit timeline run.mcap --from 10 --to 20 --every

  trace-audit timeline logs/amr-7/ --from +3600 --to +3900 --json
"""


@app.command("timeline", help=help_text(_TIMELINE_HELP))
def timeline_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    start: FromOption = None,
    end: ToOption = None,
    every: Annotated[bool, typer.Option("--every", help="A row per cycle.")] = False,
    robot: RobotsOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    path, answers = guarded(lambda: timeline_each_robot(log, start, end, every, robot or ()))
    emit_per_robot(path, answers, timeline_doc, json_out=json_out, plain=plain)


def timeline_each_robot(
    source: Path, start: str | None, end: str | None, every: bool, robots: Sequence[str]
) -> tuple[str, list[Timeline]]:
    """Each selected robot's timeline of the window (read in each robot's own clock); a
    robot with no time in the window is left out."""
    from trace_audit.log_source import as_log
    from trace_audit.log_time import NotWallClockError
    from trace_audit.selection import Selection, per_robot
    from trace_audit.transitions import WindowOutsideLogError, timeline

    log = Selection(tuple(robots)).of(as_log(source))
    answers = per_robot(
        log,
        lambda one: timeline(one, start=start, end=end, every=every),
        skip=(WindowOutsideLogError, NotWallClockError),
    )
    return str(log.root), answers


def timeline_doc(r: Timeline) -> Doc:
    """The timeline as a document: one table, or one per run of the robot's clock."""
    doc = Doc()
    doc.title(f"{r.robot}: {fmt_t(r.start_ns, r.clock)} .. {fmt_t(r.end_ns, r.clock)}")
    changes = r.changes
    doc.line(
        f"{r.cycles} cycles, {changes} decision change{'s' if changes != 1 else ''}, "
        f"{len(r.gaps)} gap{'s' if len(r.gaps) != 1 else ''}"
        + ("; recovered from an unfinished segment" if r.recovered else "")
        + ("; live: the log is being written" if r.live else "")
    )
    if not r.clock_runs:
        _timeline_table(doc, r, list(r.rows), list(r.gaps))
        return doc
    # The clock restarted: each run is its own sequence (times start again lower), so the
    # runs are shown one after the other, never merged by time.
    doc.line(
        Seg(
            f"The robot's clock went back {len(r.clock_runs) - 1} time(s) in this log: each "
            "run of its clock is shown on its own.",
            "yellow",
        )
    )
    for step in r.clock_steps:
        how = "stepped back (declared by its writer)" if step.declared else "restarted lower"
        doc.line(
            f"  before cycle {step.first_cycle}: the clock {how} by {step.back_ns / 1e9:.3f} s, "
            f"from {r.clock.show(step.from_ns)} to {r.clock.show(step.to_ns)}"
        )
    for number, run in enumerate(r.clock_runs):
        cycles = (
            f"cycles {run.first_cycle}..{run.last_cycle}"
            if run.first_cycle is not None
            else "no cycle in the window"
        )
        shown = run.segments[0] if len(run.segments) == 1 else f"{run.segments[0]}.."
        doc.line(f"clock run {number + 1} of {len(r.clock_runs)}: {cycles} ({shown})")
        in_run = [g for g in r.gaps if _in_run(g.after_cycle, run)]
        _timeline_table(doc, r, [row for row in r.rows if row.run == number], in_run)
    return doc


def _in_run(cycle: int, run: ClockRun) -> bool:
    first, last = run.first_cycle, run.last_cycle
    return first is not None and last is not None and first <= cycle <= last


def _timeline_table(doc: Doc, r: Timeline, rows: list[TimelineRow], gaps: list[Gap]) -> None:
    events: list[tuple[int, int, list[Line]]] = []
    for row in rows:
        lead = f"{row.leading.label} = {row.leading.shown}" if row.leading else "-"
        flags = ", ".join(f"{k} x{v}" if v > 1 else k for k, v in row.flag_counts.items())
        what: list[str | Seg] = [lead]
        if row.max_deviation is not None:
            what.append(f"; max deviation {fmt_value(row.max_deviation)} {row.deviation_unit}")
        if flags:
            what.append(Seg(f"; flags: {flags}", "bold red"))
        if row.scenario:
            what.append(Seg(f" [{row.scenario}]", "dim"))
        command = row.command or "?"
        held = fmt_duration(row.held_ns)
        events.append(
            (
                row.t_ns,
                0,
                [
                    _cell(r, row.t_ns),
                    str(row.cycle),
                    Seg(command, "bold yellow" if row.previous != row.command else ""),
                    f"{held} / {row.cycles}" if not r.every else held,
                    what,
                ],
            )
        )
    for gap in gaps:
        events.append((gap.after_t_ns, 1, _gap_row(gap, _cell(r, gap.after_t_ns))))
    events.sort(key=lambda e: (e[0], e[1]))
    doc.table(
        [
            Column("t (UTC)" if r.clock.wall else "t (s)", "right"),
            Column("cycle", "right"),
            Column("decision"),
            Column("held / cycles" if not r.every else "held", "right"),
            Column("leading factor, flags", wrap=True),
        ],
        [e[2] for e in events],
    )


def _cell(r: Timeline, t_ns: int) -> str:
    """A row's time: seconds, or on a wall clock the UTC time of day (the whole ISO time
    when the row falls on another day than the window's start)."""
    if not r.clock.wall:
        return f"{t_ns / 1e9:.3f}"
    shown, start = r.clock.iso(t_ns, digits=3), r.clock.iso(r.start_ns, digits=3)
    return shown[11:-1] if shown[:10] == start[:10] else shown


def _gap_row(gap: Gap, when: str) -> list[Line]:
    """A timeline row for a gap: how long beyond the period, the cycles it would have held,
    and what the seal after it declares."""
    declared = gap.declared_dropped
    said = "" if declared is None else f", {declared} declared dropped by the seal after it"
    return [
        when,
        "",
        Seg("GAP", "bold red"),
        fmt_duration(gap.gap_ns),
        Seg(
            f"no cycle between {gap.after_cycle} and {gap.before_cycle} "
            f"(~{gap.missing_cycles} missing{said})",
            "red",
        ),
    ]
