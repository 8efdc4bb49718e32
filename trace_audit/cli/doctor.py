"""trace-audit ``doctor``: does a log follow the TRACE profile (schemas/PROFILE.md)?

Parses its arguments, calls ``trace_audit.doctor.doctor_log`` and renders the typed report:
rich on a terminal, plain text with ``--plain`` or in a pipe, JSON with ``--json``.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Seg
from trace_audit.cli.options import (
    CheckedLogArgument,
    EvidencePaths,
    JsonOption,
    PlainOption,
    RobotsOption,
    evidence_option,
)
from trace_audit.cli.output import emit, progress_bar, setup_logging

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from trace_audit.doctor import DoctorReport, Problem, SegmentDoctor

_HELP = """Check a log against every rule of the TRACE profile: the tool to run first when
you write TRACE logs from C++, Rust or anything else.

Checks the MCAP header, trace.session keys and ranges, channels and schemas, message
encodings, that log_time = t_ns and sequence = cycle, the order of messages within a cycle,
compact JSON and each record's JSON Schema, seals and the hash chain, checkpoints, declared
drops, evidence refs, and the summary and indexes. Each problem names the rule, the
PROFILE.md section, MUST or SHOULD, and where it is (cycle, file offset).

Evidence refs into external recordings (rosbag2 MCAP) are checked when the recordings are
given with --evidence; otherwise they are a note, never a broken rule.

Exit codes: 0 conforming (SHOULD deviations are listed as notes), 1 a MUST is broken,
2 usage, 3 unreadable (missing, not MCAP).

[bold]Examples[/bold]:

  trace-audit doctor robot.mcap

  trace-audit doctor robot.mcap --evidence rosbag2_2026_11_29/ --plain

  trace-audit doctor /data/logs/amr-7/ --json | jq '.segments[].problems'

  trace-audit doctor /data/fleet/ --robot amr-7 --robot amr-9
"""

_MAX_LISTED = 100


@app.command("doctor", help=help_text(_HELP))
def doctor_command(
    log: CheckedLogArgument,
    *,
    robot: RobotsOption = None,
    evidence: Annotated[EvidencePaths, evidence_option("that evidence refs")] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.doctor import doctor_log

    setup_logging()
    robots = robot or ()
    if json_out or plain or not sys.stderr.isatty():
        report = guarded(lambda: doctor_log(log, robots=robots, evidence=evidence or ()))
    else:
        with progress_bar("checking records (MB)") as bar:
            task = bar.task_ids[0]

            def progress(done: int, total: int) -> None:
                bar.update(task, completed=done >> 20, total=total >> 20)

            report = guarded(
                lambda: doctor_log(log, robots=robots, evidence=evidence or (), progress=progress)
            )
    emit(report, doctor_doc, json_out=json_out, plain=plain)
    if not report.conforms:
        raise typer.Exit(EXIT_FINDINGS)


def doctor_doc(r: DoctorReport) -> Doc:
    """The doctor report as a document."""
    doc = Doc()
    errors, notes = r.errors, r.notes
    verdict = (
        Seg("CONFORMS", "bold green")
        if r.conforms
        else Seg(f"{len(errors)} RULE(S) BROKEN", "bold red", f"{len(errors)} RULE(S) BROKEN")
    )
    doc.title([f"Doctor {r.path}: ", verdict])
    several = len(r.robots) > 1
    doc.fields(
        [
            *([("robots", ", ".join(r.robots))] if several else []),
            ("segments", str(len(r.segments))),
            ("read", f"{sum(s.messages for s in r.segments)} messages, "
             f"{sum(s.cycles for s in r.segments)} sealed cycles" + _summarised(r)),
            ("rules", f"{r.rules_checked} rules of PROFILE.md"),
            ("evidence", ", ".join(r.evidence) if r.evidence else "no external recording given"),
        ]
    )  # fmt: skip
    if errors:
        doc.heading("MUST broken (the log does not conform)")
        _problem_table(doc, r.located("MUST"), several=several)
    if notes:
        doc.heading("SHOULD not followed (notes)")
        _problem_table(doc, r.located("SHOULD"), several=several)
    return doc


def _problem_table(
    doc: Doc, problems: list[tuple[SegmentDoctor, Problem]], *, several: bool
) -> None:
    """One row a problem; on a log of several robots, each first names its robot (or, for
    a file no robot owns, the file)."""
    rows = []
    for segment, p in problems[:_MAX_LISTED]:
        where = []
        if p.cycle is not None:
            where.append(f"cycle {p.cycle}")
        if p.offset is not None:
            where.append(f"@{p.offset}")
        times = f" (x{p.count})" if p.count > 1 else ""
        row = [f"{p.section} {p.rule}", " ".join(where), p.message + times]
        if several:
            row.insert(0, segment.robot or segment.path.rsplit("/", 1)[-1])
        rows.append(row)
    columns = [Column("rule"), Column("where"), Column("what", wrap=True)]
    doc.table([Column("robot"), *columns] if several else columns, rows)
    if len(problems) > _MAX_LISTED:
        doc.line(f"… and {len(problems) - _MAX_LISTED} more (--json lists all)", 2)


def _summarised(r: DoctorReport) -> str:
    """What was not checked: warm summaries are pruned layers, not the layer records."""
    n = sum(s.summarised for s in r.segments)
    if not n:
        return ""
    return (
        f" ({n} of them warm summaries: their pruned layers are checked for stamps and "
        "order, not against the layer schemas)"
    )
