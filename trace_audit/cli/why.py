"""``trace-audit why``: every transition into an action, with the reason logged for it.

Parses its arguments, calls ``trace_audit.transitions.why`` and renders the typed result:
rich on a terminal, plain text with ``--plain`` or in a pipe, JSON with ``--json``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any

import typer

from trace_audit.cli.app import EXIT_USAGE, app, fail, guarded, help_text
from trace_audit.cli.doc import Doc, Seg, fmt_duration, fmt_t
from trace_audit.cli.options import (
    JsonOption,
    LogArgument,
    PlainOption,
    RobotsOption,
    TimeOption,
    action_option,
)
from trace_audit.cli.output import emit_per_robot

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from collections.abc import Sequence
    from pathlib import Path

    from trace_audit.transitions import WhyResult

__all__ = ["why_command", "why_doc", "why_each_robot"]

_WHY_HELP = """Why did the robot take an action? Every transition into it, with the reason.

A transition is a cycle whose command is ACTION while the previous logged cycle's was not.
For each: when, what it changed from, how long it held, the rationale, the factors with
their values (the leading one first), the counterfactuals and any execution flags. With
--t, only the transition that led to the state at that time. ACTION is matched without
regard to case; one the log never shows is a usage error (exit 2) listing those it does.
In a root of several robots each robot's transitions are shown under its name (--robot
selects robots).

[bold]Examples[/bold]:

  trace-audit why run.mcap --action STOP

  trace-audit why run.mcap --action STOP --t 25

  trace-audit why logs/amr-7/ --action reroute --json
"""


@app.command("why", help=help_text(_WHY_HELP))
def why_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    action: Annotated[str, action_option("The command to explain, e.g. STOP.")],
    t: TimeOption = None,
    all_: Annotated[
        bool, typer.Option("--all", help="Every transition in the log (the default without --t).")
    ] = False,
    robot: RobotsOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    if all_ and t is not None:
        fail("give either --t or --all, not both", EXIT_USAGE)
    path, answers = guarded(lambda: why_each_robot(log, action, t, robot or ()))
    emit_per_robot(path, answers, why_doc, json_out=json_out, plain=plain)


def why_each_robot(
    source: Path, action: str, t: str | None, robots: Sequence[str]
) -> tuple[str, list[WhyResult]]:
    """Each selected robot's answer; a robot that never takes the action (or has no
    decision at ``t``) is left out. ``t`` is read in each robot's own clock."""
    from trace_audit.log_source import as_log
    from trace_audit.log_time import NotWallClockError
    from trace_audit.selection import Selection, per_robot
    from trace_audit.transitions import ActionNotTakenError, why
    from trace_runtime.errors import TimeOutOfRangeError

    log = Selection(tuple(robots)).of(as_log(source))
    answers = per_robot(
        log,
        lambda one: why(one, action, t=t),
        skip=(ActionNotTakenError, TimeOutOfRangeError, NotWallClockError),
    )
    return str(log.root), answers


def why_doc(r: WhyResult) -> Doc:
    """The transitions into an action as a document."""
    doc = Doc()
    n = len(r.transitions)
    scope = (
        f"in force at t={fmt_t(r.t_ns, r.clock)}"
        if r.t_ns is not None
        else (f"{n} transition{'s' if n != 1 else ''}")
    )
    doc.title([f"Why {r.action}? ", f"{r.robot}, {scope}"])
    if r.recovered:
        doc.line("(log recovered from an unfinished segment)")
    elif r.live:
        doc.line("(live: the log is being written)")
    for i, tr in enumerate(r.transitions, 1):
        doc.heading(f"#{i}  t={fmt_t(tr.t_ns, r.clock)}  cycle {tr.cycle}")
        before = (
            f"{tr.previous} (cycle {tr.previous_cycle})"
            if tr.previous is not None
            else "nothing: the log starts here"
        )
        if tr.unlogged_before:
            n = tr.unlogged_before
            before += f"; {n} cycle{'s' if n != 1 else ''} in between not logged"
        held = fmt_duration(tr.held_ns)
        if tr.ongoing:
            until = "and still holds at the end of the log"
        else:
            until = f"until {fmt_t(tr.ended_t_ns or 0, r.clock)}, then {tr.next_command or '?'}"
        rows: list[tuple[str, Any]] = [
            ("Changed from", before),
            ("Held", f"{held} ({tr.held_cycles} cycles) {until}"),
        ]
        rationale: list[Any] = [tr.rationale if tr.rationale is not None else "not logged"]
        if tr.truncated:
            rationale.append(Seg("  [TRUNCATED]", "bold red"))
        rows.append(("Reason", rationale))
        if tr.factors:
            lead = tr.factors[0]
            rows.append(
                (
                    "Leading factor",
                    [Seg(f"{lead.label} = {lead.shown}", "bold"), f"  ({lead.node})"],
                )
            )
            others = "; ".join(f"{f.label} = {f.shown}" for f in tr.factors[1:])
            if others:
                rows.append(("Other factors", others))
        else:
            rows.append(("Factors", Seg("none logged", "red")))
        if tr.counterfactuals:
            rows.append(("What-ifs", "; ".join(c.text for c in tr.counterfactuals)))
        rows.append(("Flags", Seg(", ".join(tr.flags), "bold red") if tr.flags else "none"))
        doc.fields(rows)
    if r.t_ns is None and len(r.actions_present) > 1:
        doc.heading("Cycles per command")
        doc.line(", ".join(f"{c}: {k}" for c, k in r.actions_present.items()), 2)
    return doc
