"""Verifies a whole log: each robot's chain walked across its segments in number order (and
every copy of a segment), the notes no single segment can tell (where the chain starts, a
clock restart between segments, cycles no checkpoint vouches for yet), and the fan-out of
one task per robot over an executor.

Along each chain the robot's Merkle tree (profile 1.2) is carried from segment to segment, so
each 1.2 checkpoint's tree is recomputed from the seals (``checkpoint_check.TreeCheck``).

``verify(log, key=)`` takes a ``logset.Log`` (which copy of a segment is read and which
files could not be read are decided there) and returns a ``VerifyReport``.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.clock import clock_restarted, show_instant
from trace_runtime.errors import LogReadError
from trace_runtime.gaps import CycleRange
from trace_runtime.reading.copies import copy_rank, cut_short_copy
from trace_runtime.reading.logset import FileProblem, Log
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import GENESIS
from trace_runtime.session import EXCERPT_METADATA
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.rotation import KeyChain
from trace_runtime.verification.recording_check import RecordingCheck
from trace_runtime.verification.report import (
    Finding,
    RobotSummary,
    SegmentSummary,
    VerifyReport,
    describe_numbers,
    display_name,
)
from trace_runtime.verification.scan import Anchor, ChainTail
from trace_runtime.verification.sink import FindingSink
from trace_runtime.verification.tree_segment import TreeSegmentCheck

__all__ = ["problem_finding", "verify"]


def problem_finding(problem: FileProblem) -> Finding:
    """A file of the log that could not be read: ``damaged``, or a ``skipped_file`` note when
    it is not a TRACE segment at all (a foreign MCAP file)."""
    return Finding(
        kind="skipped_file" if problem.foreign else "damaged",
        message=f"{problem.path.name}: {problem.reason}",
        segment=display_name(problem.path),
    )


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
    they shadow); the copy ``copies.preferred_copies`` reads is the one counted. The files
    ``log.problems`` lists become ``damaged`` findings, or ``skipped_file`` notes when foreign.
    """
    sink = FindingSink()
    for problem in log.problems:
        finding = problem_finding(problem)
        (sink.note if problem.foreign else sink.finding)(finding)
    segments = [*log.segments, *sorted(log.shadowed, key=copy_rank)]
    report = VerifyReport(str(log.root), key.key_id if key else None, key is not None)
    by_robot: dict[str, list[Segment]] = {}
    for segment in segments:
        by_robot.setdefault(segment.session.robot_id, []).append(segment)
    if executor is None:
        for robot_id in sorted(by_robot):
            chain = _RobotChain(robot_id, key, sink, report, recordings=recordings)
            report.robots.append(chain.walk(by_robot[robot_id]))
    else:
        _verify_on(executor, by_robot, key, recordings, sink=sink, report=report)
    if key is None and any(s.checkpoints for s in report.segments):
        sink.note(
            Finding(
                kind="signatures_unchecked",
                message="no public key given (--key): checkpoint "
                "signatures were not checked, so a chain recomputed by someone "
                "else would not be detected",
            )
        )
    _total(report, sink)
    if report.cycles == 0 and report.ok:
        # Nothing to vouch for: an empty log (exit 3, as info and explain say), not CLEAN.
        raise LogReadError(str(log.root), "the log holds no decision cycles")
    return report


def _total(report: VerifyReport, sink: FindingSink) -> None:
    """The report's verdict and totals: the segments read first counted once each."""
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
    for robot in report.robots:
        report.recording_windows += robot.recording_windows
        report.recording_messages += robot.recording_messages
        report.recording_checked += robot.recording_checked
    merged = CycleRange.merge_all(r.cycle_range for r in report.robots)
    if merged is not None:
        report.cycle_range = merged


# --- one robot's chain -------------------------------------------------------------------------


class _RobotChain:
    """Walks one robot's segments in number order, each entered where the last one ended."""

    def __init__(
        self,
        robot_id: str,
        key: PublicKey | None,
        sink: FindingSink,
        report: VerifyReport,
        *,
        recordings: Recordings | None = None,
    ) -> None:
        self.robot = RobotSummary(robot_id)
        self.key = key
        self.keys = KeyChain(key)
        """The robot's checkpoint key, followed through the rotations its chain announces."""
        self.sink = sink
        self.report = report
        self.recordings = recordings
        self.recorded = RecordingCheck(recordings)
        """The windows of the robot's recordings its chain sealed (profile 1.4)."""
        self.tail: ChainTail | None = None
        self.previous: int | None = None
        self.anchor: Anchor | None = None
        self.tree: CompactRange | None = None
        """The robot's Merkle tree through the chain so far; None where it is not known."""

    def walk(self, segments: Sequence[Segment]) -> RobotSummary:
        """Verify every segment (each in every copy) and return the robot's summary."""
        by_number: dict[int, list[Segment]] = {}
        for segment in segments:
            by_number.setdefault(segment.session.segment, []).append(segment)
        declared_before = self.sink.declared
        for number in sorted(by_number):
            # The copy the log reads first, then the ones it shadows.
            self._segment(number, by_number[number])
        self.recorded.finish()
        robot = self.robot
        robot.recording_windows = self.recorded.windows
        robot.recording_messages = self.recorded.messages
        robot.recording_checked = self.recorded.checked
        robot.declared_dropped = self.sink.declared - declared_before
        if segments:
            robot.clock = segments[0].session.clock
        if self.anchor is not None:
            robot.anchored_cycle, robot.anchored_ns = self.anchor.cycle, self.anchor.t_ns
        robot.announced_keys = list(self.keys.announced)
        robot.key_rotations = list(self.keys.rotations)
        self._note_unanchored()
        return robot

    def _segment(self, number: int, copies: list[Segment]) -> None:
        """One segment number: each copy checked from where the chain stands, then the
        robot's range, anchor and tail moved on past it."""
        entry, entry_cycle = self._entry(number, copies[0])
        entry_tree = self._entry_tree(number, copies[0], entry)
        results = self._check_copies(number, copies, entry, entry_cycle, entry_tree)
        if len(copies) > 1:
            self._compare_copies(number, copies, results)
        main = results[0]
        robot, summary = self.robot, main.summary
        robot.segments += 1
        robot.cycles += summary.cycles
        robot.cycles_valid += summary.cycles_valid
        robot.cycles_summarised += summary.cycles_summarised
        robot.cycle_range = summary.cycle_range.merge(robot.cycle_range)
        for r in results:
            if r.anchor is not None and (
                self.anchor is None or r.anchor.cycle >= self.anchor.cycle
            ):
                self.anchor = r.anchor
        self._note_restart(number, copies[0], summary)
        if main.tail is not None:
            self.tail = main.tail  # an empty segment (killed before its first write) passes it on
        self.tree = main.exit_tree
        self.keys = main.keys
        self.previous = number

    def _entry_tree(self, number: int, first: Segment, entry: str | None) -> CompactRange | None:
        """The tree before segment ``number``'s first seal: empty at the robot's genesis,
        the previous segment's at the end of it, None where the chain was not followed."""
        if self.previous is None:
            at_genesis = number == 0 and entry == GENESIS and first.session.prev_seal == GENESIS
            return CompactRange() if at_genesis else None
        return self.tree if entry is not None else None

    def _entry(self, number: int, first: Segment) -> tuple[str | None, int | None]:
        """The seal digest segment ``number``'s first seal must name, and the cycle it sealed
        (None, None across a missing segment: the chain cannot be followed over the hole)."""
        session, tail, robot_id = first.session, self.tail, self.robot.robot_id
        if self.previous is None:
            excerpt = first.metadata.get(EXCERPT_METADATA)
            if number == 0 and excerpt is not None and session.first_cycle > 0:
                self.sink.note(
                    Finding(
                        kind="chain_start",
                        message=f"the log is an excerpt from cycle {session.first_cycle} of "
                        f"{excerpt.get('source', '?')}; the cycles before it are not in it",
                        robot_id=robot_id,
                        segment=display_name(first.path),
                        segment_no=number,
                    )
                )
                return session.prev_seal, None
            if number == 0:
                return GENESIS, -1
            self.sink.note(
                Finding(
                    kind="chain_start",
                    message=f"the log starts at segment {number}; earlier "
                    "segments are not in it (retention)",
                    robot_id=robot_id,
                    segment=display_name(first.path),
                    segment_no=number,
                )
            )
            return session.prev_seal, None
        if number != self.previous + 1:
            missing = list(range(self.previous + 1, number))
            self.sink.finding(
                Finding(
                    kind="missing_segment",
                    message=f"segment(s) {describe_numbers(missing)} of robot {robot_id} are "
                    f"missing between cycle {tail.cycle if tail else '?'} and segment {number}",
                    robot_id=robot_id,
                    segment=display_name(first.path),
                    segment_no=number,
                    where=CycleRange(
                        first_cycle=tail.cycle + 1 if tail else None,
                        start_ns=tail.t_ns if tail else None,
                    ),
                )
            )
            return None, None
        if tail is None:
            return session.prev_seal, None
        return tail.digest, tail.cycle

    def _check_copies(
        self,
        number: int,
        copies: list[Segment],
        entry: str | None,
        entry_cycle: int | None,
        entry_tree: CompactRange | None,
    ) -> list[TreeSegmentCheck]:
        results: list[TreeSegmentCheck] = []
        prev_seal = copies[0].session.prev_seal
        for n, copy in enumerate(copies):
            # Further copies report their findings; their notes would repeat the first's.
            check = TreeSegmentCheck(
                copy,
                entry,
                entry_cycle,
                self.key,
                self.sink if n == 0 else self.sink.quiet(),
                recordings=self.recordings,
                recorded=self.recorded if n == 0 else None,
                entry_tree=entry_tree,
                # Each copy follows the rotations from where the chain stands.
                keys=self.keys.copy(),
            )
            check.run()
            check.summary.copy = n > 0
            results.append(check)
            self.report.segments.append(check.summary)
            if copy.session.prev_seal != prev_seal:
                self.sink.finding(
                    Finding(
                        kind="modified",
                        message="copies of a segment disagree on where the chain enters",
                        robot_id=self.robot.robot_id,
                        segment=check.name,
                        segment_no=number,
                    )
                )
        return results

    def _compare_copies(
        self, number: int, copies: list[Segment], results: list[TreeSegmentCheck]
    ) -> None:
        """Several copies of one segment: noted, and a finding when they fork."""
        first = copies[0]
        tiers = ", ".join(c.session.tier for c in copies)
        # A copy cut short ends at an earlier seal of the same chain: not a fork.
        cut = [r for r in results[1:] if cut_short_copy(r.segment, first)]
        also = f"; {len(cut)} of them cut short (a prefix of it)" if cut else ""
        self.sink.note(
            Finding(
                kind="duplicate_segment",
                message=f"segment {number} is present {len(copies)} "
                f"times ({tiers}); each copy was verified{also}",
                robot_id=self.robot.robot_id,
                segment=display_name(first.path),
                segment_no=number,
            )
        )
        tails = {r.tail.digest if r.tail else None for r in results if r not in cut}
        if len(tails) > 1:
            self.sink.finding(
                Finding(
                    kind="modified",
                    message=f"copies of segment {number} end in different chain heads",
                    robot_id=self.robot.robot_id,
                    segment=display_name(first.path),
                    segment_no=number,
                )
            )

    def _note_restart(self, number: int, first: Segment, summary: SegmentSummary) -> None:
        """A segment that starts on a clock that went back since its predecessor ended."""
        tail, start = self.tail, summary.cycle_range.start_ns
        if tail is None or start is None or not clock_restarted(tail.t_ns, start):
            return
        at = summary.cycle_range.first_cycle
        stepped, clock = first.session.clock_step_from_ns, first.session.clock
        begins = show_instant(start, clock)
        message = (
            f"the robot's clock restarted: segment {number} starts at {begins}, not after "
            f"cycle {tail.cycle} at {show_instant(tail.t_ns, clock)} (PROFILE section 4 allows "
            "it across segments"
            if stepped is None
            else f"the robot's clock stepped back {(stepped - start) / 1e9:.3f} s before cycle "
            f"{at} (from {show_instant(stepped, clock)} to {begins}), as its writer declared "
            f"in segment {number}: a new clock run, not tampering (PROFILE section 4"
        )
        self.sink.note(
            Finding(
                kind="clock_restart" if stepped is None else "clock_step",
                message=f"{message}; a time may name a decision in each run: explain by "
                "--cycle, or read each run apart)",
                robot_id=self.robot.robot_id,
                segment=display_name(first.path),
                segment_no=number,
                where=CycleRange(at, at, start, start),
            )
        )

    def _note_unanchored(self) -> None:
        """Cycles after the last anchor chain-verify, but no checkpoint vouches for them."""
        robot, anchor = self.robot, self.anchor
        last = robot.cycle_range.last_cycle
        if last is None or (anchor is not None and anchor.cycle >= last):
            return
        first_unanchored = anchor.cycle + 1 if anchor else robot.cycle_range.first_cycle
        assert first_unanchored is not None
        robot.unanchored_cycles = _count_after(
            self.report.segments, robot.robot_id, first_unanchored - 1
        )
        self.sink.note(
            Finding(
                kind="unanchored",
                message=f"cycles {first_unanchored}..{last} chain-verify but no checkpoint "
                "vouches for them yet (the robot crashed or is still writing, or its "
                "checkpoints were lost)",
                robot_id=robot.robot_id,
                where=CycleRange(
                    first_unanchored,
                    last,
                    anchor.t_ns if anchor else robot.cycle_range.start_ns,
                    robot.cycle_range.end_ns,
                ),
            )
        )


def _count_after(segments: list[SegmentSummary], robot_id: str, after: int) -> int:
    total = 0
    for s in segments:
        first, last = s.cycle_range.first_cycle, s.cycle_range.last_cycle
        if s.robot_id != robot_id or first is None or last is None:
            continue
        if first > after:
            total += s.cycles
        elif last > after:
            total += last - after
    return total


# --- the fan-out over an executor --------------------------------------------------------------


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
    sink = FindingSink()
    report = VerifyReport("", None, False)
    chain = _RobotChain(task.robot_id, task.key, sink, report, recordings=task.recordings)
    robot = chain.walk(segments)
    return _RobotResult(robot, report.segments, sink.findings, sink.notes, sink.declared)


def _verify_on(
    executor: Executor,
    by_robot: dict[str, list[Segment]],
    key: PublicKey | None,
    recordings: Recordings | None,
    *,
    sink: FindingSink,
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
