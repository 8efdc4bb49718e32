"""trace-audit ``verify``: is a log what the robot wrote (``cli/keygen.py`` makes the keys).

It parses its arguments, calls one library function (``trace_audit.verify.verify_log``) and
renders the typed result: rich on a terminal, plain text with ``--plain`` or in a pipe, JSON
with ``--json``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, EXIT_USAGE, app, fail, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Seg, fmt_duration, fmt_t
from trace_audit.cli.options import (
    CheckedLogArgument,
    EvidencePaths,
    JsonOption,
    PlainOption,
    RobotsOption,
    SchedulerOption,
    cluster,
    evidence_option,
    key_option,
)
from trace_audit.cli.output import emit, setup_logging

if TYPE_CHECKING:  # the library is imported inside each command: start-up stays light
    from trace_audit.log_time import LogClock
    from trace_audit.verify import (
        Finding,
        RobotSummary,
        SegmentSummary,
        VerifyReport,
        WitnessedVerifyReport,
    )
    from trace_audit.witness.compare import WitnessReport
    from trace_runtime.tlog.rotation import KeyRotation

_VERIFY_HELP = """Verify that a log is what the robot wrote: all of it, unaltered, in order.

Checks every cycle's layer messages (and the sensor readings its evidence cites) against its
seal, every seal against the previous one (across segments and restarts), every checkpoint's
chain head against the log, and, with --key, every checkpoint's Ed25519 signature. Works on
hot, warm and cold segments and on segments recovered after a crash.

Findings (exit 1), each located by robot, segment, cycles and time: modified record,
evidence mismatch, missing / inserted / reordered cycles, unsealed cycle, undeclared gap,
truncated segment, missing segment, checkpoint mismatch, bad signature, key mismatch,
unsigned checkpoint, damaged segment, tree mismatch (a profile 1.2 checkpoint's Merkle tree),
and with --witness truncated tail and fork. --witness asks about the robots the log holds;
--expect names more (a fleet's robots), so one whose every segment was deleted is found.

Not findings, reported as notes: cycles the logger declared dropped, warm summary cycles
(chain verified, payloads not retained), cycles after the last checkpoint of a crashed
robot (they chain-verify, but no signature vouches for them yet), and a clock that stepped
back within a segment (PROFILE section 4 forbids it; the seals still chain).

Without --key the chain is checked but a log re-chained by someone else is not detected.
With --key, key rotations the chain announces (profile 1.5, signed by the key before) are
followed: give the robot's first key; a checkpoint under a key never announced, or under
one rotated away from, is a key mismatch.
With --scheduler, a root of several robots is verified on a Dask cluster, one task per
robot. Exit codes: 0 clean, 1 findings, 2 usage (e.g. a bad key file), 3 unreadable input.

[bold]Examples[/bold]:

  trace-audit verify run.mcap --key keys/trace-ed25519.pub

  trace-audit verify /data/fleet/amr-7/ --key amr-7.pub --plain

  trace-audit verify run.mcap --json | jq .findings

  trace-audit verify /data/fleet/ --scheduler tcp://10.0.0.5:8786
"""

_MAX_LISTED = 200


_WitnessOption = Annotated[
    str | None,
    typer.Option(
        "--witness",
        help="Compare with what a witness cosigned: its URL, a file of cosigned checkpoint "
        "notes, or 'local' (the root's witness/ store). A log that ends before the "
        "witnessed tree is truncated_tail, one with another root a fork.",
        show_default=False,
    ),
]
_WitnessKeyOption = Annotated[
    str | None,
    typer.Option(
        "--witness-key",
        help="The witness's verifier key (witness vkey --cosignature): its cosignatures "
        "are checked.",
        show_default=False,
    ),
]
_ExpectOption = Annotated[
    list[str] | None,
    typer.Option(
        "--expect",
        help="With --witness: a robot (or its origin) the witness is asked about even if "
        "the log holds none of its segments: one it cosigned a tree of is a "
        "truncated_tail (every segment deleted). Repeat for a fleet's robots.",
        show_default=False,
    ),
]
_VerifyKeyOption = Annotated[
    Path | None,
    key_option(
        "The robot's Ed25519 public key (PEM, OpenSSH or 32 raw bytes), or the pkcs11: URI "
        "of its key in a token (read from the token)."
    ),
]
_VerifyEvidenceOption = Annotated[
    EvidencePaths, evidence_option(then=": their digests are checked there. Repeat for several.")
]


@app.command("verify", help=help_text(_VERIFY_HELP))
def verify_command(
    log: CheckedLogArgument,
    *,
    key: _VerifyKeyOption = None,
    evidence: _VerifyEvidenceOption = None,
    scheduler: SchedulerOption = None,
    robot: RobotsOption = None,
    witness: _WitnessOption = None,
    witness_key: _WitnessKeyOption = None,
    expect: _ExpectOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.verify import verify_log, verify_witnessed
    from trace_runtime.tlog.keys import load_public_key

    setup_logging()
    if expect and witness is None:
        fail("--expect asks a witness about robots: give --witness too", EXIT_USAGE)

    def run() -> VerifyReport | WitnessedVerifyReport:
        public = load_public_key(key) if key is not None else None
        with cluster(scheduler) as executor:
            if witness is None:
                return verify_log(
                    log, key=public, evidence=evidence or (), executor=executor,
                    robots=robot or (),
                )  # fmt: skip
            return verify_witnessed(
                log, witness, key=public, witness_key=witness_key, evidence=evidence or (),
                executor=executor, robots=robot or (), expected=expect or (),
            )  # fmt: skip

    report = guarded(run)
    emit(report, _verify_doc, json_out=json_out, plain=plain)
    if not report.ok:
        raise typer.Exit(EXIT_FINDINGS)


def _verify_doc(r: VerifyReport | WitnessedVerifyReport) -> Doc:
    """The verify report as a document; with --witness, the witness's section after it."""
    from trace_audit.verify import WitnessedVerifyReport

    if not isinstance(r, WitnessedVerifyReport):
        return verify_doc(r)
    doc = verify_doc(r.report)
    _witness_section(doc, r.report, r.witness)
    return doc


def _witness_section(doc: Doc, r: VerifyReport, w: WitnessReport) -> None:
    clocks = _robot_clocks(r.robots)
    doc.heading(f"Witness ({w.source})")
    rows: list[tuple[str, str | Seg]] = [
        (
            "cosignatures",
            f"checked with {w.witness_key.split('+')[0]}"
            if w.witness_key
            else Seg("not checked (no --witness-key)", "yellow"),
        ),
        ("witnessed checkpoints", str(w.witnessed)),
    ]
    for b in w.bounds:
        rows.append(
            (
                f"{b.robot_id}: logged by",
                f"cycles up to {b.cycle} (robot clock t = {fmt_t(b.t_ns, clocks.get(b.robot_id))}) "
                f"were logged no later than {b.time} by witness {b.witness} "
                f"(tree size {b.tree_size})",
            )
        )
    rows += [("not compared", line) for line in w.unmatched]
    doc.fields(rows)


def verify_doc(r: VerifyReport) -> Doc:
    """The verify report as a document."""
    doc = Doc()
    n = len(r.findings)
    verdict = (
        Seg("CLEAN", "bold green", "CLEAN")
        if r.ok
        else Seg(f"{n} FINDING{'S' if n != 1 else ''}", "bold red")
    )
    doc.title([f"Verify {r.path}: ", verdict])
    rows: list[tuple[str, str | Seg]] = [
        (
            "signatures",
            f"checked with key {r.key_id[:16]}…"
            if r.key_id
            else Seg("not checked (no --key): a re-chained log would pass", "yellow"),
        ),
    ]
    for robot in r.robots:
        prefix = f"{robot.robot_id}: " if len(r.robots) > 1 else ""
        rows += _robot_rows(robot, prefix)
    rows += [
        ("cycles", f"{r.cycles_valid} valid of {r.cycles} ({r.cycles_summarised} summarised)"),
        ("checkpoints", f"{r.checkpoints_valid} valid of {r.checkpoints}"),
        ("segments", f"{r.segments_valid} valid of {len(r.segments)}"),
        ("declared gaps", f"{r.declared_dropped} cycle(s) dropped by the logger"),
    ]
    rows += _recording_rows(r)
    doc.fields(rows)
    clocks = _robot_clocks(r.robots)
    if r.findings:
        doc.heading("Findings")
        _finding_table(doc, r.findings, clocks)
    if r.notes:
        doc.heading("Notes (not tampering)")
        _finding_table(doc, r.notes, clocks)
    if len(r.segments) > 1:
        _segment_table(doc, r.segments)
    return doc


def _recording_rows(r: VerifyReport) -> list[tuple[str, str]]:
    """What verify checked outside the log: refs into recordings, and recorded messages
    sealed in windows (profile 1.4)."""
    rows: list[tuple[str, str]] = []
    if r.external_resolved or r.external_unresolved:
        rows.append(
            (
                "external evidence",
                f"{r.external_resolved} ref(s) resolved in the robot's recordings"
                + (
                    f", {r.external_unresolved} not checked (recording not given: --evidence)"
                    if r.external_unresolved
                    else ""
                ),
            )
        )
    if r.recording_windows:
        unchecked = r.recording_windows - r.recording_checked
        rows.append(
            (
                "recordings",
                f"{r.recording_messages:,} recorded message(s) sealed in "
                f"{r.recording_windows:,} window(s), cited or not: "
                + (
                    "each checked against the recording"
                    if not unchecked
                    else f"{unchecked:,} window(s) not checked (recording not here)"
                ),
            )
        )
    return rows


def _segment_table(doc: Doc, segments: list[SegmentSummary]) -> None:
    doc.heading("Segments")
    doc.table(
        [
            Column("segment"),
            Column("tier"),
            Column("cycles", "right"),
            Column("range"),
            Column("checkpoints", "right"),
            Column("status"),
        ],
        [
            [
                Path(s.path).name,
                s.tier + (" (recovered)" if s.recovered else ""),
                str(s.cycles),
                f"{s.cycle_range.first_cycle}..{s.cycle_range.last_cycle}"
                if s.cycle_range.first_cycle is not None
                else "-",
                f"{s.checkpoints_valid}/{s.checkpoints}",
                Seg("ok", "green") if s.ok else Seg(f"{s.findings} finding(s)", "red"),
            ]
            for s in segments
        ],
    )


def _robot_rows(robot: RobotSummary, prefix: str) -> list[tuple[str, str | Seg]]:
    r = robot.cycle_range
    if r.first_cycle is None or r.start_ns is None or r.end_ns is None:
        return [(f"{prefix}range", "no sealed cycles")]
    from trace_audit.log_time import LogClock

    span = fmt_duration(r.end_ns - r.start_ns)
    clock = LogClock(robot.clock, r.start_ns)
    rows: list[tuple[str, str | Seg]] = [
        (
            f"{prefix}validated range",
            f"cycles {r.first_cycle}..{r.last_cycle}, t = {fmt_t(r.start_ns, clock)} .. "
            f"{fmt_t(r.end_ns, clock)} ({span}, {robot.segments} segment(s))",
        )
    ]
    if robot.anchored_cycle is None or robot.anchored_ns is None:
        rows.append((f"{prefix}anchored", Seg("no checkpoint vouches for any cycle", "yellow")))
    else:
        tail = (
            f"; the last {robot.unanchored_cycles} cycle(s) are not anchored yet"
            if robot.unanchored_cycles
            else ""
        )
        rows.append(
            (
                f"{prefix}anchored",
                f"through cycle {robot.anchored_cycle} "
                f"(t = {fmt_t(robot.anchored_ns, clock)}){tail}",
            )
        )
    return rows + [(f"{prefix}key rotated", _rotation(k)) for k in robot.key_rotations]


def _rotation(k: KeyRotation) -> str:
    """A rotation by both of a key's names: its key id (keygen's, verify's) and the C2SP
    verifier key's name+hash (what a note's signature line and a witness show)."""
    before = f"key {k.from_key_id[:16]}…" if k.from_key_id else "no key"
    return (
        f"at cycle {k.cycle}, announced by {before}, to key {k.to_key_id[:16]}… "
        f"(vkey {'+'.join(k.to_vkey.split('+')[:2])})"
    )


def _robot_clocks(robots: list[RobotSummary]) -> dict[str, LogClock]:
    """Each robot's clock, so a finding's time reads as the robot's other times do."""
    from trace_audit.log_time import LogClock

    return {r.robot_id: LogClock(r.clock, r.cycle_range.start_ns or 0) for r in robots}


def _finding_table(doc: Doc, findings: list[Finding], clocks: dict[str, LogClock]) -> None:
    rows = []
    for f in findings[:_MAX_LISTED]:
        at = f.where
        if at.first_cycle is None:
            cycles = ""
        elif at.last_cycle is None or at.last_cycle == at.first_cycle:
            cycles = str(at.first_cycle)
        else:
            cycles = f"{at.first_cycle}..{at.last_cycle}"
        clock = clocks.get(f.robot_id or "")
        when = fmt_t(at.start_ns, clock) if at.start_ns is not None else ""
        rows.append([f.kind, f.segment or f.robot_id, cycles, when, f.message])
    doc.table(
        [Column("kind"), Column("where"), Column("cycles"), Column("t"), Column("what", wrap=True)],
        rows,
    )
    if len(findings) > _MAX_LISTED:
        doc.line(f"… and {len(findings) - _MAX_LISTED} more (--json lists all)", 2)
