"""Is this log what the robot wrote, all of it, in order? The one verification of a log.

In the spirit of CloudTrail's ``validate-logs``: every cycle is checked against its seal
(``integrity.verify_cycle``), every seal against the previous one (across segments and
restarts), every checkpoint's head against the chain and its signature against the robot's
public key. Problems are located (robot, segment, cycle range, time range) and classified:

- tampering: a modified record, missing / inserted / reordered cycles, a finished segment cut
  short, a missing segment, a checkpoint that does not match the chain, a bad signature,
  another key, an unsigned checkpoint when a key was expected;
- not tampering, reported as notes: cycles the logger declared dropped (``seal.dropped``),
  warm-tier summary cycles (chain verified, payloads not retained), and the tail of a crashed
  segment that no checkpoint vouches for yet (it still chain-verifies up to the cut).

``verify(log, key=)`` takes a ``logset.Log`` (which copy of a segment is read and which files
could not be read are decided there) and returns a ``VerifyReport`` whose ``segments`` say,
per file, whether it verified. The investigator's ``trace-audit verify`` and the runtime's
retention (which deletes only segments that verify) both stand on it. See docs/integrity.md.
"""

from __future__ import annotations

import bisect
from array import array
from collections.abc import Iterator
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from trace_runtime.cycles import Cycle
from trace_runtime.errors import LogReadError, RecordError
from trace_runtime.integrity import (
    CheckpointState,
    PublicKey,
    SealStatus,
    check_checkpoint,
    decode_checkpoint,
    iter_checkpoints,
    verify_cycle,
)
from trace_runtime.logset import FileProblem, Log, copy_rank, cut_short_copy
from trace_runtime.reader import Segment
from trace_runtime.recordings import ExternalCheck, Recordings
from trace_runtime.records import GENESIS, Checkpoint
from trace_runtime.session import TIER_METADATA, TIERS

__all__ = [
    "Finding",
    "FindingKind",
    "NoteKind",
    "RobotSummary",
    "SegmentSummary",
    "VerifyReport",
    "is_external_evidence",
    "problem_finding",
    "verify",
]

FindingKind = Literal[
    "modified",
    "evidence_mismatch",
    "missing",
    "inserted",
    "reordered",
    "unsealed",
    "undeclared_gap",
    "truncated",
    "missing_segment",
    "checkpoint_mismatch",
    "bad_signature",
    "key_mismatch",
    "unsigned_checkpoint",
    "damaged",
]
"""What a finding says happened; every kind makes ``verify`` exit 1."""

Span = tuple[int | None, int | None, int | None, int | None]
"""Where a finding is: (first cycle, last cycle, start ns, end ns), each None if unknown."""
NOWHERE: Span = (None, None, None, None)

NoteKind = Literal[
    "declared_gap",
    "summarised",
    "unanchored",
    "recovered",
    "signatures_unchecked",
    "chain_start",
    "duplicate_segment",
    "skipped_file",
    "uncovered_sensors",
    "no_checkpoints",
    "external_unresolved",
    "clock_backwards",
    "clock_restart",
]
"""Things an investigator should know that are not tampering."""


@dataclass(frozen=True, slots=True)
class Finding:
    """One located problem (or note): what, where in the log, which cycles and times."""

    kind: str
    message: str
    robot_id: str = ""
    segment: str = ""
    segment_no: int | None = None
    first_cycle: int | None = None
    last_cycle: int | None = None
    start_ns: int | None = None
    end_ns: int | None = None

    def covers(self, cycle: int) -> bool:
        """True when ``cycle`` lies in the finding's cycle range."""
        if self.first_cycle is None:
            return False
        last = self.first_cycle if self.last_cycle is None else self.last_cycle
        return self.first_cycle <= cycle <= last


@dataclass(slots=True)
class SegmentSummary:
    """What verify saw in one segment file."""

    path: str
    robot_id: str
    number: int
    tier: str
    finished: bool
    recovered: bool
    cycles: int = 0
    cycles_valid: int = 0
    cycles_summarised: int = 0
    checkpoints: int = 0
    checkpoints_valid: int = 0
    first_cycle: int | None = None
    last_cycle: int | None = None
    start_ns: int | None = None
    end_ns: int | None = None
    findings: int = 0
    ok: bool = True
    last_seal: str | None = None
    """Digest of the segment's last seal in reading order: where the next segment enters."""
    copy: bool = False
    """A second copy of a segment (mid-compaction): verified, but not counted twice."""
    external_resolved: int = 0
    """Evidence refs into external recordings that resolved with a matching digest."""
    external_unresolved: int = 0
    """Evidence refs into external recordings that were not given (not checked)."""


@dataclass(slots=True)
class RobotSummary:
    """One robot's chain: the validated range and how much of it a checkpoint vouches for."""

    robot_id: str
    segments: int = 0
    cycles: int = 0
    cycles_valid: int = 0
    cycles_summarised: int = 0
    declared_dropped: int = 0
    first_cycle: int | None = None
    last_cycle: int | None = None
    start_ns: int | None = None
    end_ns: int | None = None
    anchored_cycle: int | None = None
    """Last cycle a matching (and, with a key, validly signed) checkpoint vouches for."""
    anchored_ns: int | None = None
    unanchored_cycles: int = 0
    """Cycles after ``anchored_cycle``: chained, but no checkpoint vouches for them yet."""


@dataclass(slots=True)
class VerifyReport:
    """The result of ``verify_log``; ``ok`` is False when there is any finding."""

    path: str
    key_id: str | None
    signatures_checked: bool
    robots: list[RobotSummary] = field(default_factory=list)
    segments: list[SegmentSummary] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)
    notes: list[Finding] = field(default_factory=list)
    cycles: int = 0
    cycles_valid: int = 0
    cycles_summarised: int = 0
    checkpoints: int = 0
    checkpoints_valid: int = 0
    segments_valid: int = 0
    declared_dropped: int = 0
    external_resolved: int = 0
    """Evidence refs into external recordings (--evidence) that resolved, digests equal."""
    external_unresolved: int = 0
    """Evidence refs into external recordings that were not given: unchecked, not broken."""
    first_cycle: int | None = None
    last_cycle: int | None = None
    start_ns: int | None = None
    end_ns: int | None = None
    ok: bool = True
    """No finding: every cycle read verifies (notes may still say what is not covered)."""


# --- one segment -------------------------------------------------------------------------------


@dataclass(slots=True)
class _Tail:
    """Where a segment's chain ends: the next segment's first seal must name ``digest``."""

    digest: str
    cycle: int
    t_ns: int


@dataclass(slots=True)
class _Anchor:
    cycle: int
    t_ns: int


@dataclass(slots=True)
class _Scan:
    """Per sealed cycle, in reading order: number, time, digest prefixes, link check."""

    num: array[int] = field(default_factory=lambda: array("q"))
    t: array[int] = field(default_factory=lambda: array("q"))
    dig: array[int] = field(default_factory=lambda: array("Q"))
    prev: array[int] = field(default_factory=lambda: array("Q"))
    dropped: array[int] = field(default_factory=lambda: array("q"))
    link_ok: bytearray = field(default_factory=bytearray)
    last_digest: str | None = None
    heads: dict[int, list[str]] = field(default_factory=dict)
    unsealed: list[tuple[int, int, int]] = field(default_factory=list)  # (position, cycle, t)
    summarised: list[int] = field(default_factory=list)  # positions
    bad_positions: set[int] = field(default_factory=set)
    uncited: int = 0  # sensor readings no evidence ref with a digest names
    external_ok: int = 0  # evidence refs into external recordings that resolved and match
    external_unresolved: dict[str, int] = field(default_factory=dict)  # recording -> refs
    damaged: list[tuple[int, int, int]] = field(default_factory=list)
    """Cycle ranges lost in damaged chunks: (first, last, sealed cycles lost)."""
    backsteps: list[tuple[int, int, int, int]] = field(default_factory=list)
    """Where time went backwards: (cycle, t, the cycle before, its t)."""
    absent_open: dict[str, _AbsentRun] = field(default_factory=dict)  # recording -> open run
    absent_runs: list[_AbsentRun] = field(default_factory=list)


@dataclass(slots=True)
class _AbsentRun:
    """Consecutive citing cycles whose refs name messages a given recording does not hold."""

    recording: str
    first: tuple[int, int]  # (cycle, t)
    last: tuple[int, int]
    refs: int
    detail: str  # the first one


_EXTERNAL = "external recording"
"""Named in the message of every finding about a ref into an external recording (changed
or absent), so ``is_external_evidence`` can tell them from in-log refs."""


def is_external_evidence(finding: Finding) -> bool:
    """True for an evidence mismatch of a ref into an external recording (PROFILE section 11),
    whether the message it names differs or is not there."""
    return finding.kind == "evidence_mismatch" and _EXTERNAL in finding.message


def _prefix(hex_digest: str) -> int:
    try:
        return int(hex_digest[:16], 16)
    except ValueError:
        return 0


class _SegmentCheck:
    """Verifies one segment given where the robot's chain stood before it."""

    def __init__(
        self,
        segment: Segment,
        entry: str | None,
        entry_cycle: int | None,
        key: PublicKey | None,
        add: _Sink,
        *,
        recordings: Recordings | None = None,
    ) -> None:
        self.segment = segment
        self.recordings = recordings
        self.session = segment.session
        self.name = _display_name(segment.path)
        self.entry = entry
        self.entry_cycle = entry_cycle
        self.key = key
        self.sink = add
        info = segment.info
        self.summary = SegmentSummary(
            path=str(segment.path),
            robot_id=self.session.robot_id,
            number=self.session.segment,
            tier=self.session.tier,
            finished=info.finished,
            recovered=info.recovered,
        )
        self.scan = _Scan()
        self.checkpoints: list[tuple[int, int, Checkpoint | None]] = []  # (log time, seq, ckpt)
        self.anchor: _Anchor | None = None
        self.tail: _Tail | None = None
        self.findings_before = len(add.findings)

    # --- reporting helpers ---------------------------------------------------------------

    def finding(self, kind: FindingKind, message: str, span: Span = NOWHERE) -> None:
        robot, name, number = self.session.robot_id, self.name, self.session.segment
        self.sink.finding(Finding(kind, message, robot, name, number, *span))

    def note(self, kind: NoteKind, message: str, span: Span = NOWHERE) -> None:
        robot, name, number = self.session.robot_id, self.name, self.session.segment
        self.sink.note(Finding(kind, message, robot, name, number, *span))

    # --- passes ------------------------------------------------------------------------------

    def run(self) -> None:
        self._read_checkpoints()
        self._scan_cycles()
        self._report_absent_runs()
        self._report_damaged_chunks()
        self._check_structure()
        self._check_unsealed()
        self._check_checkpoints()
        scan = self.scan
        s = self.summary
        s.cycles = len(scan.num) + len(scan.unsealed)
        s.cycles_summarised = len(scan.summarised)
        s.cycles_valid = len(scan.num) - len(scan.bad_positions)
        if scan.num:
            s.first_cycle, s.last_cycle = min(scan.num), max(scan.num)
            s.start_ns, s.end_ns = min(scan.t), max(scan.t)
        if scan.last_digest is not None and scan.num:
            self.tail = _Tail(scan.last_digest, scan.num[-1], scan.t[-1])
        s.last_seal = scan.last_digest
        s.external_resolved = scan.external_ok
        s.external_unresolved = sum(scan.external_unresolved.values())
        s.findings = len(self.sink.findings) - self.findings_before
        s.ok = s.findings == 0
        if scan.summarised:
            first, last = scan.summarised[0], scan.summarised[-1]
            self.note(
                "summarised",
                f"{len(scan.summarised)} cycle(s) are warm-tier summaries: summarised (chain "
                "verified, payloads not retained)",
                (scan.num[first], scan.num[last], scan.t[first], scan.t[last]),
            )
        if scan.uncited:
            self.note(
                "uncovered_sensors",
                f"{scan.uncited} sensor reading(s) are cited by no evidence ref with a digest: "
                "the chain does not cover them",
                (s.first_cycle, s.last_cycle, s.start_ns, s.end_ns),
            )
        if scan.external_unresolved:
            self._note_external_unresolved()
        if scan.backsteps:
            self._note_clock_backwards()
        if s.recovered:
            self.note(
                "recovered",
                "segment has no summary (the robot crashed or the disk "
                "filled); read by a linear scan",
                (s.first_cycle, s.last_cycle, s.start_ns, s.end_ns),
            )

    def _note_clock_backwards(self) -> None:
        # Not tampering (the seals chain), but the profile forbids it, and it makes a time in
        # this segment name more than one decision: the investigator must be told.
        steps = self.scan.backsteps
        cycle, t_ns, before, before_ns = steps[0]
        more = f" and {len(steps) - 1} more time(s)" if len(steps) > 1 else ""
        self.note(
            "clock_backwards",
            f"the robot's clock stepped back within the segment: cycle {cycle} is "
            f"{(before_ns - t_ns) / 1e9:.3f} s earlier than cycle {before}{more} (PROFILE "
            "section 4 forbids it; the chain is intact, but a time here may name more than "
            "one decision)",
            (cycle, steps[-1][0], t_ns, steps[-1][1]),
        )

    def _note_external_unresolved(self) -> None:
        s, missing = self.summary, self.scan.external_unresolved
        names = ", ".join(sorted(missing)[:5]) + (" …" if len(missing) > 5 else "")
        self.note(
            "external_unresolved",
            f"{sum(missing.values())} evidence ref(s) name external recordings that were not "
            f"given ({names}): not checked, not broken; pass them with --evidence",
            (s.first_cycle, s.last_cycle, s.start_ns, s.end_ns),
        )

    def _read_checkpoints(self) -> None:
        try:
            for message in iter_checkpoints(self.segment):
                try:
                    checkpoint: Checkpoint | None = decode_checkpoint(message.data)
                except RecordError:
                    checkpoint = None
                self.checkpoints.append((message.log_time_ns, message.sequence, checkpoint))
        except LogReadError as err:  # a damaged file is a finding, not a crash
            self.finding("damaged", f"cannot read the segment's checkpoints: {err}")

    def _report_damaged_chunks(self) -> None:
        """A chunk the reader stepped over (fails its CRC, does not decompress) is damage to
        the file, located by the chunk's time range and the cycles read around it."""
        scan = self.scan
        for offset, reason in self.segment.skipped_chunks:
            span = self.segment.chunk_span(offset)
            if span is None:
                self.finding("damaged", f"part of the segment cannot be read: {reason}")
                continue
            start_ns, end_ns = span
            before = [n for n, t in zip(scan.num, scan.t, strict=True) if t < start_ns]
            after = [i for i, t in enumerate(scan.t) if t > end_ns]
            first = max(before) + 1 if before else None
            last = min(scan.num[i] for i in after) - 1 if after else None
            lost = "the cycles in it cannot be counted"
            if first is not None and last is not None and first <= last:
                lost = f"cycles {first}..{last} are in it"
                # The cycle after the damage declares the drops among those numbers.
                next_position = min(after, key=lambda i: scan.num[i])
                sealed = last - first + 1 - scan.dropped[next_position]
                scan.damaged.append((first, last, max(sealed, 0)))
            self.finding(
                "damaged",
                f"part of the segment cannot be read: {reason} (t = {start_ns / 1e9:.3f} s .. "
                f"{end_ns / 1e9:.3f} s; {lost}, unverifiable)",
                (first, last, start_ns, end_ns),
            )

    def _iter_cycles_resuming(self) -> Iterator[Cycle]:
        """Every readable cycle; a damaged chunk becomes a finding and reading goes on after it."""
        start: int | None = None
        tried: set[int | None] = set()
        last_t: int | None = None
        while start not in tried:
            tried.add(start)
            try:
                for cycle in self.segment.iter_cycles(start_ns=start):
                    if last_t is not None and cycle.t_ns <= last_t and start is not None:
                        continue
                    last_t = cycle.t_ns
                    yield cycle
                return
            except LogReadError as err:  # a damaged file is a finding, not a crash
                after = last_t if last_t is not None else -1
                self.finding(
                    "damaged",
                    f"part of the segment cannot be read: {err}",
                    (None, None, after if after >= 0 else None, None),
                )
                later = [c.start_ns for c in self.segment.chunks() if c.start_ns > after]
                if len(later) < 2:
                    return
                start = later[1]  # skip the chunk that failed (the first one after ``after``)

    def _scan_cycles(self) -> None:
        scan = self.scan
        wanted = {c.cycle for _, _, c in self.checkpoints if c is not None}
        expected = self.entry
        before: tuple[int, int] | None = None
        for cycle in self._iter_cycles_resuming():
            if before is not None and cycle.t_ns < before[1]:
                scan.backsteps.append((cycle.cycle, cycle.t_ns, *before))
            before = (cycle.cycle, cycle.t_ns)
            status = verify_cycle(cycle)
            if status.state == "unsealed":
                scan.unsealed.append((len(scan.num), cycle.cycle, cycle.t_ns))
                continue
            assert status.seal_digest is not None
            position = len(scan.num)
            scan.num.append(cycle.cycle)
            scan.t.append(cycle.t_ns)
            scan.dig.append(_prefix(status.seal_digest))
            prev = status.prev or ""
            scan.prev.append(_prefix(prev))
            scan.dropped.append(status.dropped)
            scan.link_ok.append(1 if expected is not None and prev == expected else 0)
            if position == 0:
                self._check_entry(prev, cycle)
            expected = status.seal_digest
            scan.last_digest = status.seal_digest
            if cycle.cycle in wanted:
                scan.heads.setdefault(cycle.cycle, []).append(status.seal_digest)
            scan.uncited += status.sensors_uncited
            self._content_findings(status, position)

    def _check_entry(self, prev: str, cycle: Cycle) -> None:
        """The first seal against where the chain entered the segment."""
        if self.entry is None:
            self.scan.link_ok[0] = 2  # the previous segment is missing: nothing to compare
        elif self.scan.link_ok[0] and prev != self.session.prev_seal:
            # The chain links up, but the segment's own metadata says otherwise: edited.
            self.finding(
                "modified",
                "the segment's trace.session metadata names another previous seal than its "
                "first seal does (the metadata was edited)",
                (cycle.cycle, cycle.cycle, cycle.t_ns, cycle.t_ns),
            )

    def _content_findings(self, status: SealStatus, position: int) -> None:
        if status.state == "modified":
            self.scan.bad_positions.add(position)
            self.finding(
                "modified",
                f"cycle {status.cycle}: {status.detail}",
                (status.cycle, status.cycle, status.t_ns, status.t_ns),
            )
        elif status.state == "summarised":
            self.scan.summarised.append(position)
        if status.evidence_mismatch:
            self.scan.bad_positions.add(position)
            self.finding(
                "evidence_mismatch",
                f"cycle {status.cycle}: sensor reading {', '.join(status.evidence_mismatch)} "
                "differs from the digest its evidence ref names",
                (status.cycle, status.cycle, status.t_ns, status.t_ns),
            )
        if status.external:
            self._check_external(status, position)

    def _check_external(self, status: SealStatus, position: int) -> None:
        """Evidence refs into external recordings: a changed or missing message in a
        recording that was given is a finding; a recording not given is only counted."""
        broken: list[str] = []
        scan = self.scan
        for ref in status.external:
            name = str(ref.get("recording"))
            if self.recordings is None:
                scan.external_unresolved[name] = scan.external_unresolved.get(name, 0) + 1
                continue
            check = self.recordings.check(ref)
            if check.absent:
                self._extend_absent_run(check, status)
                scan.bad_positions.add(position)
                continue
            ended = scan.absent_open.pop(name, None)  # the recording holds this one: a run ends
            if ended is not None:
                scan.absent_runs.append(ended)
            if check.state == "resolved":
                scan.external_ok += 1
            elif check.state == "unresolved":
                scan.external_unresolved[name] = scan.external_unresolved.get(name, 0) + 1
            elif check.detail not in broken:
                broken.append(check.detail)
        if broken:
            self.scan.bad_positions.add(position)
            self.finding(
                "evidence_mismatch",
                f"cycle {status.cycle}: evidence ref into an {_EXTERNAL} does not "
                f"resolve: {'; '.join(broken)}",
                (status.cycle, status.cycle, status.t_ns, status.t_ns),
            )

    def _extend_absent_run(self, check: ExternalCheck, status: SealStatus) -> None:
        # A recording cut short loses every message after the cut: one finding for the run
        # says so, where one per cycle would bury it.
        at = (status.cycle, status.t_ns)
        run = self.scan.absent_open.get(check.recording)
        if run is None:
            self.scan.absent_open[check.recording] = _AbsentRun(
                check.recording, at, at, 1, check.detail
            )
        else:
            run.last, run.refs = at, run.refs + 1

    def _report_absent_runs(self) -> None:
        scan = self.scan
        runs = sorted([*scan.absent_runs, *scan.absent_open.values()], key=lambda r: r.first)
        for run in runs:
            (first, first_ns), (last, last_ns) = run.first, run.last
            where = f"cycle {first}" if first == last else f"cycles {first}..{last}"
            if run.refs == 1:
                what = (
                    f"an evidence ref names a message that {_EXTERNAL} {run.recording} "
                    f"does not hold: {run.detail}"
                )
            else:
                # only a run says something about the recording as a whole
                what = (
                    f"{run.refs} evidence refs name messages that {_EXTERNAL} "
                    f"{run.recording} does not hold (the first: {run.detail}); a run of them "
                    "means the recording was cut short or those messages removed"
                )
            self.finding("evidence_mismatch", f"{where}: {what}", (first, last, first_ns, last_ns))
        scan.absent_runs, scan.absent_open = [], {}

    # --- the chain inside the segment ------------------------------------------------------

    def _check_structure(self) -> None:
        scan = self.scan
        n = len(scan.num)
        if n == 0:
            return
        if all(ok for ok in scan.link_ok):
            self._check_numbering(range(n))
            return
        _Structure(self, scan).classify()

    def _check_numbering(self, positions: range | list[int]) -> None:
        """Linked cycles: a numbering gap must be what the seal declares dropped."""
        scan = self.scan
        for i in positions:
            before = self.entry_cycle if i == 0 else scan.num[i - 1]
            if before is None:
                # The first cycle the log holds (earlier segments retired or lost): nothing
                # to number against, but the drops its seal declares are still drops.
                self._declared(i, None)
                continue
            self._gap(before, scan.t[i - 1] if i > 0 else None, i)

    def _declared(self, i: int, before_t: int | None) -> int:
        """Note the drops the seal at position ``i`` declares; return their count."""
        scan = self.scan
        declared, number = scan.dropped[i], scan.num[i]
        if declared:
            self.sink.declared += declared
            self.note(
                "declared_gap",
                f"{declared} cycle(s) dropped by the logger before cycle {number} "
                "(declared by its seal)",
                (number - declared, number - 1, before_t, scan.t[i]),
            )
        return declared

    def _gap(self, before: int, before_t: int | None, i: int) -> None:
        scan = self.scan
        gap = scan.num[i] - before - 1
        declared = self._declared(i, before_t)
        number, t = scan.num[i], scan.t[i]
        if gap > declared:
            scan.bad_positions.add(i)
            self.finding(
                "undeclared_gap",
                f"cycles {before + 1}..{number - 1 - declared} are missing although "
                "the chain is intact and the logger declared no drop",
                (before + 1, number - 1 - declared, before_t, t),
            )
        elif gap < 0:
            scan.bad_positions.add(i)
            self.finding(
                "reordered",
                f"cycle {number} follows cycle {before} in the chain",
                (number, before, t, t),
            )

    def _check_unsealed(self) -> None:
        scan = self.scan
        n = len(scan.num)
        for position, number, t in scan.unsealed:
            if position == n and self.summary.recovered:
                self.note(
                    "unanchored",
                    f"cycle {number} was being written when the robot "
                    "stopped: layer messages without a seal",
                    (number, number, t, t),
                )
            else:
                self.finding(
                    "unsealed",
                    f"cycle {number}: layer messages without a seal "
                    "(inserted, or its seal was removed)",
                    (number, number, t, t),
                )

    # --- checkpoints ----------------------------------------------------------------------------

    def _check_checkpoints(self) -> None:
        scan = self.scan
        session = self.session
        last_cycle = scan.num[-1] if scan.num else None
        last_t = scan.t[-1] if scan.t else None
        is_sorted = all(scan.num[i] < scan.num[i + 1] for i in range(len(scan.num) - 1))
        window_start = session.first_cycle
        final_seen: Checkpoint | None = None
        for log_time, sequence, checkpoint in self.checkpoints:
            self.summary.checkpoints += 1
            if checkpoint is None:
                self.finding(
                    "modified",
                    f"the checkpoint after cycle {sequence} is not a valid checkpoint record",
                    (sequence, sequence, log_time, log_time),
                )
                continue
            c = checkpoint
            # Located by what it claims and by where it sits (its MCAP sequence is its cycle).
            where: Span = (min(window_start, c.cycle), max(c.cycle, sequence), None, log_time)
            problems = self._checkpoint_problems(c, last_cycle, is_sorted)
            state: CheckpointState = check_checkpoint(c, self.key)
            if problems:
                kind: FindingKind = problems[0][0]
                span = where
                if kind == "truncated" and last_cycle is not None:
                    span = (last_cycle + 1, c.cycle, last_t, c.t_ns)
                self.finding(
                    kind,
                    f"checkpoint at cycle {c.cycle}: " + "; ".join(p[1] for p in problems),
                    span,
                )
            if state in ("bad_signature", "key_mismatch", "unsigned"):
                messages = {
                    "bad_signature": "its signature does not verify with the given key",
                    "key_mismatch": f"it is signed by another key ({(c.key_id or '?')[:16]}…)",
                    "unsigned": "it is not signed, but a key was given",
                }
                kind = "unsigned_checkpoint" if state == "unsigned" else state
                self.finding(
                    kind,
                    f"checkpoint at cycle {c.cycle}: {messages[state]}; "
                    f"cycles {window_start}..{c.cycle} are not vouched for",
                    where,
                )
            if not problems and state in ("valid", "unchecked"):
                self.summary.checkpoints_valid += 1
                if self.anchor is None or c.cycle >= self.anchor.cycle:
                    self.anchor = _Anchor(c.cycle, c.t_ns)
                window_start = c.cycle + 1
            if c.final:
                final_seen = c
        # A segment its logger closed ends with its closing checkpoint; one without a summary
        # (a crash) cannot have one. Compacted tiers carry checkpoints over with the cycles.
        if _closed_by_logger(self.segment) and last_cycle is not None:
            if not self.checkpoints:
                self._no_checkpoints(last_cycle, last_t)
            elif final_seen is None:
                anchored = f"cycle {self.anchor.cycle}" if self.anchor else "none"
                self.finding(
                    "truncated",
                    "the segment was finished but has no closing checkpoint: its end was cut "
                    f"after cycle {last_cycle} (last checkpoint: {anchored})",
                    (last_cycle + 1, None, last_t, None),
                )
            elif final_seen.cycle < last_cycle:
                after = [i for i in range(len(scan.num)) if scan.num[i] > final_seen.cycle]
                self.finding(
                    "inserted",
                    f"cycles after the closing checkpoint (cycle {final_seen.cycle}): "
                    f"{len(after)} cycle(s) appended",
                    (final_seen.cycle + 1, last_cycle, final_seen.t_ns, last_t),
                )
                scan.bad_positions.update(after)

    def _no_checkpoints(self, last_cycle: int, last_t: int | None) -> None:
        """A closed segment without a single checkpoint: its writer skips PROFILE §6's SHOULD.

        Nothing shows that its end was cut (a writer that checkpoints at all closes with a
        final one, so a missing final among others is ``truncated``), but nothing vouches for
        its end either. With a key the investigator expects signatures: then it is a finding.
        """
        first_t = min(self.scan.t) if self.scan.t else None
        span: Span = (self.session.first_cycle, last_cycle, first_t, last_t)
        if self.key is not None:
            self.finding(
                "unsigned_checkpoint",
                "a key was given but the segment holds no checkpoint: no signature vouches "
                f"for cycles {self.session.first_cycle}..{last_cycle}",
                span,
            )
            return
        self.note(
            "no_checkpoints",
            "end not anchored: no final checkpoint (the segment holds no checkpoints at all; "
            "its writer skips the SHOULD of PROFILE §6, so a cut end could not be told)",
            (last_cycle, last_cycle, last_t, last_t),
        )

    def _checkpoint_problems(
        self, c: Checkpoint, last_cycle: int | None, is_sorted: bool
    ) -> list[tuple[FindingKind, str]]:
        problems: list[tuple[FindingKind, str]] = []
        session = self.session
        if c.robot_id != session.robot_id:
            problems.append(("checkpoint_mismatch", f"names robot {c.robot_id!r}"))
        if c.segment != session.segment:
            problems.append(
                ("checkpoint_mismatch", f"it was written in segment {c.segment}, not this one")
            )
        heads = self.scan.heads.get(c.cycle)
        if not heads:
            if last_cycle is not None and c.cycle > last_cycle:
                problems.append(
                    (
                        "truncated",
                        f"it vouches for cycle {c.cycle} but the segment "
                        f"ends at cycle {last_cycle}: the end was cut",
                    )
                )
            else:
                problems.append(
                    ("checkpoint_mismatch", f"its head cycle {c.cycle} is not in the log")
                )
            return problems
        if c.head not in heads:
            problems.append(
                (
                    "checkpoint_mismatch",
                    "the chain head it vouches for differs "
                    "from the log's seal: records up to it were altered and the chain "
                    "recomputed",
                )
            )
        if c.segment == session.segment and c.first_cycle == session.first_cycle:
            num = self.scan.num
            if is_sorted:
                count = bisect.bisect_right(num, c.cycle) - bisect.bisect_left(num, c.first_cycle)
            else:
                count = sum(1 for n in num if c.first_cycle <= n <= c.cycle)
            # Cycles lost in damaged chunks were sealed; the damage finding accounts for them.
            count += sum(
                lost for a, b, lost in self.scan.damaged if c.first_cycle <= a and b <= c.cycle
            )
            if count != c.sealed:
                problems.append(
                    (
                        "checkpoint_mismatch",
                        f"it counts {c.sealed} sealed cycles "
                        f"from cycle {c.first_cycle}, the log has {count}",
                    )
                )
        return problems


class _Structure:
    """Explains broken links inside a segment: which cycles were removed, added or moved.

    ``pred[i]`` is the position of the cycle whose seal digest cycle ``i``'s seal names. In an
    intact segment it is ``i - 1`` everywhere. Reading the exceptions: cycles a link skips
    over and that no later cycle continues from were inserted; of the rest, those outside the
    longest run in increasing cycle number (seals bind the numbers) were moved; a predecessor
    nowhere in the log is a removed cycle (when numbers are missing) or an altered seal (when
    they are not).
    """

    ENTRY = -1
    NONE = -2

    def __init__(self, check: _SegmentCheck, scan: _Scan) -> None:
        self.check = check
        self.scan = scan
        n = len(scan.num)
        self.n = n
        where: dict[int, int] = {}
        self.duplicates: list[tuple[int, int]] = []
        for i in range(n):
            if scan.dig[i] in where:
                self.duplicates.append((where[scan.dig[i]], i))
            else:
                where[scan.dig[i]] = i
        entry = _prefix(check.entry) if check.entry is not None else None
        self.pred: list[int] = []
        for i in range(n):
            if i > 0 and scan.link_ok[i] == 1:
                self.pred.append(i - 1)
            elif (i == 0 and scan.link_ok[i]) or (entry is not None and scan.prev[i] == entry):
                self.pred.append(self.ENTRY)
            else:
                self.pred.append(where.get(scan.prev[i], self.NONE))
        self.succ: list[list[int]] = [[] for _ in range(n)]
        for i, p in enumerate(self.pred):
            if p >= 0:
                self.succ[p].append(i)

    def _descendants(self, start: int) -> set[int]:
        """Positions reached by following links forward from ``start`` (itself included)."""
        seen: set[int] = set()
        stack = [start]
        while stack:
            node = stack.pop()
            if node not in seen:
                seen.add(node)
                stack.extend(self.succ[node])
        return seen

    def _ancestors(self, start: int) -> set[int]:
        """Positions reached by following links back from ``start``."""
        seen: set[int] = set()
        node = self.pred[start]
        while node >= 0 and node not in seen:
            seen.add(node)
            node = self.pred[node]
        return seen

    def classify(self) -> None:
        check, scan, pred = self.check, self.scan, self.pred
        n = self.n
        inserted: set[int] = set()
        for original, copy in self.duplicates:
            # A second copy of an existing cycle: the copy is the one the chain does not use.
            extra = copy if pred[copy] != copy - 1 or not self.succ[copy] else original
            inserted.add(extra)
            check.finding(
                "inserted",
                f"cycle {scan.num[extra]} appears twice; the copy is not part of the chain",
                (scan.num[extra], scan.num[extra], scan.t[extra], scan.t[extra]),
            )
        # A link that skips cycles: those no later cycle continues from were inserted.
        # ``next_open`` jumps over positions already found inserted, so many links that skip
        # back to one place (a flood of seals naming the start) cost linear time, not n^2.
        jump = list(range(n + 1))
        for k in inserted:
            jump[k] = k + 1

        def next_open(k: int) -> int:
            root = k
            while jump[root] != root:
                root = jump[root]
            while jump[k] != root:
                jump[k], k = root, jump[k]
            return root

        for i in range(n):
            p = pred[i]
            if scan.link_ok[i] or not (0 <= p < i - 1 or (p == self.ENTRY and i > 0)):
                continue
            skipped: list[int] = []
            k = next_open(max(p, -1) + 1)
            while k < i:
                if k not in inserted:
                    skipped.append(k)
                k = next_open(k + 1)
            if not skipped:
                continue
            # Skipped cycles that continue the chain, before or after ``i``, were moved.
            chain = self._descendants(i) | self._ancestors(i)
            dead = [k for k in skipped if k not in chain]
            inserted.update(dead)
            for k in dead:
                jump[k] = k + 1
            after = f"after cycle {scan.num[p]}" if p >= 0 else "at the start of the segment"
            for run in _runs(dead):
                numbers = sorted({scan.num[k] for k in run})
                check.finding(
                    "inserted",
                    f"{len(run)} cycle(s) not in the chain {after} "
                    f"(numbered {_describe_numbers(numbers)})",
                    (numbers[0], numbers[-1], scan.t[run[0]], scan.t[run[-1]]),
                )
        # Order: seals bind cycle numbers, so the longest run of the remaining cycles in
        # increasing number stayed in place and every other one was moved.
        rest = [i for i in range(n) if i not in inserted]
        kept = _longest_increasing([scan.num[i] for i in rest])
        moved = {rest[j] for j in range(len(rest)) if j not in kept}
        self._report_moved(rest, moved)
        scan.bad_positions.update(inserted | moved)
        # A seal named by nobody, or naming a seal that is nowhere: removed or altered.
        explained = inserted | moved
        for i in range(n):
            if scan.link_ok[i] or i in explained:
                continue
            if pred[i] >= 0 or pred[i] == self.ENTRY:
                # Linked (to the entry, or a prefix match the full digest disagreed with).
                if pred[i] == i - 1 or (pred[i] == self.ENTRY and i == 0):
                    self._unknown_link(i)
                continue
            q = i - 1
            while q >= 0 and q in explained:
                q -= 1
            self._no_predecessor(i, q, explained)
        # Numbering gaps along the links that hold.
        for i in range(n):
            if scan.link_ok[i] != 1 or i in explained or (i > 0 and i - 1 in explained):
                continue
            if i > 0:
                check._gap(scan.num[i - 1], scan.t[i - 1], i)
            elif check.entry_cycle is not None:
                check._gap(check.entry_cycle, None, i)
            else:
                check._declared(i, None)

    def _report_moved(self, rest: list[int], moved: set[int]) -> None:
        """One finding per run of moved cycles, located between the cycles around it."""
        scan = self.scan
        j = 0
        while j < len(rest):
            if rest[j] not in moved:
                j += 1
                continue
            k = j
            while k + 1 < len(rest) and rest[k + 1] in moved:
                k += 1
            run = [rest[x] for x in range(j, k + 1)]
            before = rest[j - 1] if j > 0 else None
            after = rest[k + 1] if k + 1 < len(rest) else None
            around = [i for i in (before, after) if i is not None]
            numbers = [scan.num[i] for i in run]
            span = [scan.num[i] for i in run + around]
            times = [scan.t[i] for i in run + around]
            if before is not None and after is not None:
                where = f"between cycles {scan.num[before]} and {scan.num[after]}"
            elif before is not None:
                where = f"after cycle {scan.num[before]}, at the end"
            elif after is not None:
                where = f"before cycle {scan.num[after]}, at the start"
            else:
                where = "alone"
            what = (
                f"cycle {numbers[0]} is"
                if len(run) == 1
                else (f"cycles {_describe_numbers(sorted(numbers))} are")
            )
            self.check.finding(
                "reordered",
                f"{what} out of chain order (found {where})",
                (min(span), max(span), min(times), max(times)),
            )
            j = k + 1

    def _unknown_link(self, i: int) -> None:
        scan = self.scan
        self.check.finding(
            "modified",
            f"cycle {scan.num[i]}: its seal does not link to the previous seal",
            (scan.num[i], scan.num[i], scan.t[i], scan.t[i]),
        )
        scan.bad_positions.add(i)

    def _no_predecessor(self, i: int, q: int, explained: set[int]) -> None:
        """Cycle ``i`` names a previous seal that is nowhere in the log.

        Cycles are missing when numbers are; otherwise a seal was altered. Which one the next
        cycle tells: if it no longer names cycle ``i`` either, ``i``'s own seal changed (its
        ``prev`` and so its digest); if it still links to ``i``, the seal before ``i`` changed.
        """
        check, scan = self.check, self.scan
        number, t = scan.num[i], scan.t[i]
        declared = scan.dropped[i]
        if q < 0:
            before, before_t = check.entry_cycle, None
            if before is None:
                if scan.link_ok[i] == 2:
                    return  # the first segment present: nothing to link to
                # Only the segment's metadata says where the chain entered, and which cycle
                # came first.
                before = check.session.first_cycle - 1
        else:
            before, before_t = scan.num[q], scan.t[q]
        scan.bad_positions.add(i)
        if number - before - 1 > declared:
            first, last = before + 1, number - 1
            if any(a <= first and last <= b for a, b, _ in scan.damaged):
                return  # lost in a damaged chunk: reported as damage, not as a removal
            check.finding(
                "missing",
                f"cycles {first}..{last} are missing ({last - first + 1} cycle(s) removed: "
                f"cycle {number} names a previous seal that is not in the log)",
                (first, last, before_t, t),
            )
            return
        nxt = i + 1 if i + 1 < self.n else None
        if nxt is not None and self.pred[nxt] == self.NONE and not scan.link_ok[nxt]:
            explained.add(nxt)
            check.finding(
                "modified",
                f"cycle {number}: its seal was altered (it names a previous seal that is not "
                f"in the log, and cycle {scan.num[nxt]} no longer names it)",
                (number, number, t, t),
            )
        elif nxt is not None and q >= 0:
            scan.bad_positions.add(q)
            check.finding(
                "modified",
                f"cycle {before}: its seal was altered or replaced "
                f"(cycle {number} names a different previous seal)",
                (before, before, before_t, before_t),
            )
        elif q >= 0:
            check.finding(
                "modified",
                f"the seal of cycle {before} or of cycle {number} was altered (cycle {number} "
                "names a previous seal that is not in the log)",
                (before, number, before_t, t),
            )
        else:
            where = (
                f"the previous segment's chain (which ends at cycle {before})"
                if check.entry_cycle is not None
                else "the chain recorded in the segment's trace.session metadata"
            )
            check.finding(
                "modified",
                f"cycle {number} does not continue {where}: a seal was altered",
                (before if check.entry_cycle is not None else number, number, None, t),
            )


def _longest_increasing(values: list[int]) -> set[int]:
    """Indexes of one longest strictly increasing subsequence of ``values`` (O(n log n))."""
    tails: list[int] = []  # smallest tail value of an increasing run of each length
    tail_at: list[int] = []  # index of that tail
    parent = [-1] * len(values)
    for i, value in enumerate(values):
        j = bisect.bisect_left(tails, value)
        if j == len(tails):
            tails.append(value)
            tail_at.append(i)
        else:
            tails[j], tail_at[j] = value, i
        parent[i] = tail_at[j - 1] if j > 0 else -1
    kept: set[int] = set()
    k = tail_at[-1] if tail_at else -1
    while k != -1:
        kept.add(k)
        k = parent[k]
    return kept


def _closed_by_logger(segment: Segment) -> bool | None:
    """Whether the segment's logger closed it (so it must end with a closing checkpoint).

    A hot segment is the logger's own file: closed when it has a summary. A compacted one is
    always finished; its ``trace.tier`` metadata says whether its hot source was
    (``source_finished``). None when it does not say: the closing checkpoint is not required.
    """
    if segment.session.tier == "hot":
        return segment.info.finished

    value = segment.metadata.get(TIER_METADATA, {}).get("source_finished")
    return None if value is None else value == "true"


def _runs(positions: list[int]) -> list[list[int]]:
    runs: list[list[int]] = []
    for p in positions:
        if runs and p == runs[-1][-1] + 1:
            runs[-1].append(p)
        else:
            runs.append([p])
    return runs


def _describe_numbers(numbers: list[int]) -> str:
    if len(numbers) == 1:
        return str(numbers[0])
    if numbers == list(range(numbers[0], numbers[-1] + 1)):
        return f"{numbers[0]}..{numbers[-1]}"
    return ", ".join(str(n) for n in numbers[:8]) + (", …" if len(numbers) > 8 else "")


def _display_name(path: Path) -> str:
    parts = path.parts
    return "/".join(parts[-2:]) if len(parts) >= 2 and parts[-2] in TIERS else path.name


# --- the whole log -------------------------------------------------------------------------------


class _Sink:
    def __init__(self) -> None:
        self.findings: list[Finding] = []
        self.notes: list[Finding] = []
        self.declared = 0
        self._seen: set[tuple[str, str, str, int | None, int | None]] = set()

    def finding(self, f: Finding) -> None:
        key = (f.kind, f.robot_id, f.segment, f.first_cycle, f.last_cycle)
        if f.kind == "modified" and key in self._seen:
            return  # a modified seal is seen from both sides of its link: report it once
        self._seen.add(key)
        self.findings.append(f)

    def note(self, f: Finding) -> None:
        self.notes.append(f)

    def quiet(self) -> _Sink:
        """A sink that shares this one's findings and drops notes and counts."""
        other = _Sink()
        other.findings = self.findings
        other._seen = self._seen
        return other


def problem_finding(problem: FileProblem) -> Finding:
    """A file of the log that could not be read: ``damaged``, or a ``skipped_file`` note when
    it is not a TRACE segment at all (a foreign MCAP file)."""
    name = _display_name(problem.path)
    kind = "skipped_file" if problem.foreign else "damaged"
    return Finding(kind, f"{problem.path.name}: {problem.reason}", segment=name)


def verify(
    log: Log,
    *,
    key: PublicKey | None = None,
    recordings: Recordings | None = None,
    executor: Executor | None = None,
) -> VerifyReport:
    """Verify every segment of ``log`` (each robot's chain across its segments and tiers);
    never raises on tampering or damage: those are findings.

    ``recordings``: external MCAP recordings (e.g. rosbag2) that evidence refs may name;
    a ref into a recording given that does not resolve or whose digest differs is an
    ``evidence_mismatch`` finding; refs into recordings not given are an
    ``external_unresolved`` note (PROFILE.md section 11).

    Given an ``executor`` (local processes, a Dask cluster's), each robot's chain is
    verified there as one task, by path (every worker must see the files); the results are
    merged in robot order, so the report is the one a local run gives.

    Each segment is verified in every copy the log holds (``log.segments`` and the copies
    they shadow); the copy ``logset.preferred_copies`` reads is the one counted. The files
    ``log.problems`` lists become ``damaged`` findings, or ``skipped_file`` notes when foreign.
    """
    sink = _Sink()
    for problem in log.problems:
        finding = problem_finding(problem)
        (sink.note if problem.foreign else sink.finding)(finding)
    segments = [*log.segments, *sorted(log.shadowed, key=copy_rank)]
    root = log.root
    report = VerifyReport(str(root), key.key_id if key else None, key is not None)
    by_robot: dict[str, list[Segment]] = {}
    for segment in segments:
        by_robot.setdefault(segment.session.robot_id, []).append(segment)
    if executor is None:
        for robot_id in sorted(by_robot):
            robot = _verify_robot(
                robot_id, by_robot[robot_id], key, sink, report, recordings=recordings
            )
            report.robots.append(robot)
    else:
        _verify_on(executor, by_robot, key, recordings, sink=sink, report=report)
    if key is None and any(s.checkpoints for s in report.segments):
        sink.note(
            Finding(
                "signatures_unchecked",
                "no public key given (--key): checkpoint "
                "signatures were not checked, so a chain recomputed by someone "
                "else would not be detected",
            )
        )
    report.findings = sink.findings
    report.notes = sink.notes
    report.ok = not sink.findings
    report.declared_dropped = sink.declared
    for s in report.segments:
        if s.copy:
            continue
        report.cycles += s.cycles
        report.cycles_valid += s.cycles_valid
        report.cycles_summarised += s.cycles_summarised
        report.checkpoints += s.checkpoints
        report.checkpoints_valid += s.checkpoints_valid
        report.segments_valid += 1 if s.ok else 0
        report.external_resolved += s.external_resolved
        report.external_unresolved += s.external_unresolved
    robots = [r for r in report.robots if r.first_cycle is not None]
    if robots:
        report.first_cycle = min(r.first_cycle for r in robots if r.first_cycle is not None)
        report.last_cycle = max(r.last_cycle for r in robots if r.last_cycle is not None)
        report.start_ns = min(r.start_ns for r in robots if r.start_ns is not None)
        report.end_ns = max(r.end_ns for r in robots if r.end_ns is not None)
    if report.cycles == 0 and report.ok:
        # Nothing to vouch for: an empty log (exit 3, as info and explain say), not CLEAN.
        raise LogReadError(str(log.root), "the log holds no decision cycles")
    return report


@dataclass(frozen=True, slots=True)
class _RobotTask:
    """One robot's chain to verify on a worker: its files in the order verify reads them."""

    robot_id: str
    paths: tuple[str, ...]
    key: PublicKey | None
    recordings: Recordings | None


@dataclass(frozen=True, slots=True)
class _RobotResult:
    robot: RobotSummary
    segments: list[SegmentSummary]
    findings: list[Finding]
    notes: list[Finding]
    declared: int


def _verify_robot_task(task: _RobotTask) -> _RobotResult:
    segments = [Segment(Path(p)) for p in task.paths]
    sink = _Sink()
    report = VerifyReport("", None, False)
    robot = _verify_robot(
        task.robot_id, segments, task.key, sink, report, recordings=task.recordings
    )
    return _RobotResult(robot, report.segments, sink.findings, sink.notes, sink.declared)


def _verify_on(
    executor: Executor,
    by_robot: dict[str, list[Segment]],
    key: PublicKey | None,
    recordings: Recordings | None,
    *,
    sink: _Sink,
    report: VerifyReport,
) -> None:
    """Each robot's chain as one task on ``executor``; merged in robot order as the local
    loop would have filled the sink and the report. Workers open absolute paths; the
    summaries name the files as the caller did."""
    names: dict[str, str] = {}
    tasks: list[_RobotTask] = []
    for robot_id in sorted(by_robot):
        paths = []
        for segment in by_robot[robot_id]:
            absolute = str(segment.path.resolve())
            names[absolute] = str(segment.path)
            paths.append(absolute)
        tasks.append(_RobotTask(robot_id, tuple(paths), key, recordings))
    futures = [executor.submit(_verify_robot_task, task) for task in tasks]
    for future in futures:
        result = future.result()
        report.robots.append(result.robot)
        for summary in result.segments:
            summary.path = names.get(summary.path, summary.path)
            report.segments.append(summary)
        for finding in result.findings:
            sink.finding(finding)
        for note in result.notes:
            sink.note(note)
        sink.declared += result.declared


def _verify_robot(
    robot_id: str,
    segments: list[Segment],
    key: PublicKey | None,
    sink: _Sink,
    report: VerifyReport,
    *,
    recordings: Recordings | None = None,
) -> RobotSummary:
    robot = RobotSummary(robot_id)
    by_number: dict[int, list[Segment]] = {}
    for segment in segments:
        by_number.setdefault(segment.session.segment, []).append(segment)
    tail: _Tail | None = None
    previous: int | None = None
    anchor: _Anchor | None = None
    declared_before = sink.declared
    for number in sorted(by_number):
        copies = by_number[number]  # the copy the log reads first, then the ones it shadows
        first = copies[0]
        session = first.session
        entry: str | None
        entry_cycle: int | None = None
        if previous is None:
            entry = session.prev_seal
            if number == 0:
                entry, entry_cycle = GENESIS, -1
            else:
                sink.note(
                    Finding(
                        "chain_start",
                        f"the log starts at segment {number}; earlier "
                        "segments are not in it (retention)",
                        robot_id,
                        _display_name(first.path),
                        number,
                    )
                )
        elif number != previous + 1:
            missing = list(range(previous + 1, number))
            sink.finding(
                Finding(
                    "missing_segment",
                    f"segment(s) {_describe_numbers(missing)} of robot {robot_id} are missing "
                    f"between cycle {tail.cycle if tail else '?'} and segment {number}",
                    robot_id,
                    _display_name(first.path),
                    number,
                    tail.cycle + 1 if tail else None,
                    None,
                    tail.t_ns if tail else None,
                    None,
                )
            )
            entry = None  # the chain cannot be followed across the hole
        else:
            entry = tail.digest if tail is not None else session.prev_seal
            entry_cycle = tail.cycle if tail is not None else None
        results: list[_SegmentCheck] = []
        for n, copy in enumerate(copies):
            # Further copies report their findings; their notes would repeat the first's.
            check = _SegmentCheck(
                copy,
                entry,
                entry_cycle,
                key,
                sink if n == 0 else sink.quiet(),
                recordings=recordings,
            )
            check.run()
            check.summary.copy = n > 0
            results.append(check)
            report.segments.append(check.summary)
            if copy.session.prev_seal != session.prev_seal:
                sink.finding(
                    Finding(
                        "modified",
                        "copies of a segment disagree on where the chain enters",
                        robot_id,
                        check.name,
                        number,
                    )
                )
        if len(copies) > 1:
            tiers = ", ".join(c.session.tier for c in copies)
            # A copy cut short ends at an earlier seal of the same chain: not a fork.
            cut = [r for r in results[1:] if cut_short_copy(r.segment, first)]
            also = f"; {len(cut)} of them cut short (a prefix of it)" if cut else ""
            sink.note(
                Finding(
                    "duplicate_segment",
                    f"segment {number} is present {len(copies)} "
                    f"times ({tiers}); each copy was verified{also}",
                    robot_id,
                    _display_name(first.path),
                    number,
                )
            )
            tails = {r.tail.digest if r.tail else None for r in results if r not in cut}
            if len(tails) > 1:
                sink.finding(
                    Finding(
                        "modified",
                        f"copies of segment {number} end in different chain heads",
                        robot_id,
                        _display_name(first.path),
                        number,
                    )
                )
        main = results[0]
        summary = main.summary
        robot.segments += 1
        robot.cycles += summary.cycles
        robot.cycles_valid += summary.cycles_valid
        robot.cycles_summarised += summary.cycles_summarised
        if summary.first_cycle is not None:
            robot.first_cycle = (
                summary.first_cycle
                if robot.first_cycle is None
                else min(robot.first_cycle, summary.first_cycle)
            )
            robot.last_cycle = (
                summary.last_cycle
                if robot.last_cycle is None or summary.last_cycle is None
                else max(robot.last_cycle, summary.last_cycle)
            )
            robot.start_ns = (
                summary.start_ns
                if robot.start_ns is None or summary.start_ns is None
                else min(robot.start_ns, summary.start_ns)
            )
            robot.end_ns = (
                summary.end_ns
                if robot.end_ns is None or summary.end_ns is None
                else max(robot.end_ns, summary.end_ns)
            )
        for r in results:
            if r.anchor is not None and (anchor is None or r.anchor.cycle >= anchor.cycle):
                anchor = r.anchor
        start = main.summary.start_ns
        if tail is not None and start is not None and start <= tail.t_ns:
            sink.note(
                Finding(
                    "clock_restart",
                    f"the robot's clock restarted: segment {number} starts at "
                    f"{start / 1e9:.3f} s, not after cycle {tail.cycle} at {tail.t_ns / 1e9:.3f} s "
                    "(PROFILE section 4 allows it across segments; a time may name a decision "
                    "in each run: explain by --cycle, or read each run apart)",
                    robot_id,
                    _display_name(first.path),
                    number,
                    main.summary.first_cycle,
                    main.summary.first_cycle,
                    start,
                    start,
                )
            )
        if main.tail is not None:
            tail = main.tail  # an empty segment (killed before its first write) passes it on
        previous = number
    robot.declared_dropped = sink.declared - declared_before
    if anchor is not None:
        robot.anchored_cycle, robot.anchored_ns = anchor.cycle, anchor.t_ns
    last = robot.last_cycle
    if last is not None and (anchor is None or anchor.cycle < last):
        first_unanchored = anchor.cycle + 1 if anchor else robot.first_cycle
        assert first_unanchored is not None
        robot.unanchored_cycles = _count_after(report.segments, robot_id, first_unanchored - 1)
        sink.note(
            Finding(
                "unanchored",
                f"cycles {first_unanchored}..{last} chain-verify but no checkpoint vouches for "
                "them yet (the robot crashed or is still writing, or its checkpoints were lost)",
                robot_id,
                "",
                None,
                first_unanchored,
                last,
                anchor.t_ns if anchor else robot.start_ns,
                robot.end_ns,
            )
        )
    return robot


def _count_after(segments: list[SegmentSummary], robot_id: str, after: int) -> int:
    total = 0
    for s in segments:
        if s.robot_id != robot_id or s.first_cycle is None or s.last_cycle is None:
            continue
        if s.first_cycle > after:
            total += s.cycles
        elif s.last_cycle > after:
            total += s.last_cycle - after
    return total
