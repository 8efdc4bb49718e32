"""``trace-audit info``: what a log holds, its segments, channels, drops and gaps.

Parses its arguments, calls ``trace_audit.info.log_info`` and renders the typed result:
rich on a terminal, plain text with ``--plain`` or in a pipe, JSON with ``--json``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Line, Seg, fmt_duration, fmt_t
from trace_audit.cli.options import JsonOption, LogArgument, PlainOption, RobotsOption
from trace_audit.cli.output import emit_per_robot

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from collections.abc import Sequence

    from trace_audit.info import LogInfo

__all__ = ["info_command", "info_doc", "info_each_robot"]

_INFO_HELP = """What a log holds: robot, time range, cycles, segments and tiers, channels,
dropped cycles and gaps, and whether each segment was finished or recovered.

Dropped cycles and gaps need every seal (a scan of the log); --quick answers from the
segment summaries alone. A root of several robots is described robot by robot (--robot
selects robots).

[bold]Examples[/bold]:

  trace-audit info run.mcap

  trace-audit info logs/amr-7/ --quick --json
"""


@app.command("info", help=help_text(_INFO_HELP))
def info_command(
    log: LogArgument,
    quick: Annotated[
        bool, typer.Option("--quick", help="Skip the scan of every seal (no drops or gaps).")
    ] = False,
    robot: RobotsOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    path, answers = guarded(lambda: info_each_robot(log, not quick, robot or ()))
    emit_per_robot(path, answers, info_doc, json_out=json_out, plain=plain)


def info_each_robot(source: Path, scan: bool, robots: Sequence[str]) -> tuple[str, list[LogInfo]]:
    from trace_audit.info import log_info
    from trace_audit.log_source import as_log
    from trace_audit.selection import Selection, per_robot

    log = Selection(tuple(robots)).of(as_log(source))
    return str(log.root), per_robot(log, lambda one: log_info(one, scan=scan))


def _size(n: int) -> str:
    for unit, scale in (("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def info_doc(r: LogInfo) -> Doc:
    """What a log holds as a document: a summary, then its segments, channels and gaps."""
    doc = Doc()
    doc.title(f"{', '.join(r.robots)}: {r.path}")
    doc.fields(_summary_rows(r))
    _segment_table(doc, r)
    doc.heading("Channels")
    doc.table(
        [Column("topic", wrap=True), Column("messages", "right")],
        [[topic, str(n)] for topic, n in r.channels.items()],
    )
    if r.gaps:
        _gap_table(doc, r)
    return doc


def _summary_rows(r: LogInfo) -> list[tuple[str, Line]]:
    """Time range, cycles, segments and tiers, state; drops and gaps when scanned."""
    state = (
        Seg("RECOVERED (a segment has no footer and no writer: read by scan)", "bold yellow")
        if r.recovered
        else Seg("LIVE (being written: read up to its last complete chunk)", "bold cyan")
        if r.live
        else Seg("finished", "green")
        if r.finished
        else "unfinished"
    )
    tiers = ", ".join(f"{k} x{v}" for k, v in sorted(r.tiers.items()))
    period = f"{r.period_ns / 1e6:g} ms" if r.period_ns else "?"
    rows: list[tuple[str, Line]] = [
        (
            "Time range",
            f"{fmt_t(r.start_ns, r.clock)} .. {fmt_t(r.end_ns, r.clock)} "
            f"({fmt_duration(r.duration_ns)})",
        ),
        (
            "Cycles",
            f"{r.cycles:,} (nominal period {period})"
            + ("" if r.scanned else "; sealed cycles per the summaries"),
        ),
        ("Segments", f"{len(r.segments)} ({tiers})"),
        ("State", state),
    ]
    if r.clock_steps:
        rows.append(("Clock", Seg(_clock_steps(r), "yellow")))
    if r.scanned:
        dropped = r.dropped or 0
        rows.append(
            (
                "Dropped",
                Seg(f"{dropped:,} cycles (sum of the seals' dropped)", "yellow" if dropped else ""),
            )
        )
        rows.append(
            (
                "Gaps",
                Seg(
                    f"{len(r.gaps)}, {fmt_duration(r.gap_ns)} beyond the period",
                    "yellow" if r.gaps else "",
                ),
            )
        )
    else:
        rows.append(("Dropped, gaps", "not counted (--quick)"))
    return rows


def _clock_steps(r: LogInfo) -> str:
    """Where the robot's clock went back: each step (declared by its writer) or restart."""
    shown = [
        f"{'stepped back' if s.declared else 'restarted'} {s.back_ns / 1e9:.3f} s before "
        f"cycle {s.first_cycle} ({s.segment})"
        for s in r.clock_steps[:5]
    ]
    more = f"; ... and {len(r.clock_steps) - 5} more" if len(r.clock_steps) > 5 else ""
    return "; ".join(shown) + more + " (each run of the clock is read apart)"


def _segment_table(doc: Doc, r: LogInfo) -> None:
    doc.heading("Segments")
    doc.table(
        [
            Column("file", wrap=True),
            Column("tier"),
            Column("time (UTC)" if r.clock.wall else "time (s)"),
            Column("cycles"),
            Column("size", "right"),
            Column("state"),
        ],
        [
            [
                Path(s.path).name,
                s.tier,
                _span(r, s.start_ns, s.end_ns),
                f"{s.first_cycle}..{s.last_cycle}" if s.first_cycle is not None else "-",
                _size(s.bytes),
                Seg("recovered", "yellow")
                if s.recovered
                else Seg("live", "cyan")
                if s.live
                else "ok",
            ]
            for s in r.segments
        ],
    )


def _span(r: LogInfo, start_ns: int, end_ns: int) -> str:
    """A segment's time: seconds, or on a wall clock its UTC start and end to the second."""
    if not r.clock.wall:
        return f"{start_ns / 1e9:.1f}..{end_ns / 1e9:.1f}"
    return f"{r.clock.iso(start_ns, digits=0)}..{r.clock.iso(end_ns, digits=0)[11:]}"


def _gap_table(doc: Doc, r: LogInfo) -> None:
    """The first gaps (the JSON lists them all)."""
    doc.heading("Gaps")
    shown = r.gaps[:20]
    doc.table(
        [
            Column("after cycle", "right"),
            Column("from (UTC)" if r.clock.wall else "from (s)", "right"),
            Column("beyond period", "right"),
            Column("missing", "right"),
            Column("declared", "right"),
        ],
        [
            [
                str(g.after_cycle),
                r.clock.iso(g.after_t_ns, digits=3)
                if r.clock.wall
                else f"{g.after_t_ns / 1e9:.3f}",
                fmt_duration(g.gap_ns),
                f"~{g.missing_cycles}",
                "?" if g.declared_dropped is None else str(g.declared_dropped),
            ]
            for g in shown
        ],
    )
    if len(r.gaps) > len(shown):
        doc.line(f"... and {len(r.gaps) - len(shown)} more (--json lists them all)", 2)
