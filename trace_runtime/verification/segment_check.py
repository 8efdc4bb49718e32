"""Verifies one segment given where the robot's chain stood before it: every cycle against
its seal, every seal against the one before, the numbering against the declared drops, the
checkpoints against the chain; damaged chunks, unsealed cycles and evidence refs into
external recordings; and the notes that are not tampering (summarised cycles, uncited
sensors, a clock that stepped back, a recovered file).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from trace_runtime.encoding.cycles import Cycle, RawMessage
from trace_runtime.encoding.seal_check import SealStatus, verify_cycle
from trace_runtime.errors import LogReadError, RecordError
from trace_runtime.gaps import CycleRange
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import ExternalCheck, Recordings
from trace_runtime.recording_records import TOPIC_RECORDING
from trace_runtime.records import TOPIC_CHECKPOINT, Checkpoint
from trace_runtime.tlog.checkpoints import decode_checkpoint, iter_checkpoints
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.rotation import KeyChain
from trace_runtime.verification.checkpoint_check import CheckpointCheck, ReadCheckpoint
from trace_runtime.verification.numbering import Numbering
from trace_runtime.verification.recording_check import RecordingCheck
from trace_runtime.verification.reorder import ChainOrder
from trace_runtime.verification.report import (
    EXTERNAL_RECORDING,
    SegmentSummary,
    display_name,
)
from trace_runtime.verification.scan import AbsentRun, Anchor, ChainTail, SealScan, digest_prefix
from trace_runtime.verification.sink import FindingSink, SegmentReporter

__all__ = ["SegmentCheck"]

_HELD = ("verified", "summarised")
"""Seal states in which a cycle's ``/trace/recording`` message, where kept, matches its seal."""


class SegmentCheck:
    """Verifies one segment given where the robot's chain stood before it: ``entry`` is the
    seal digest its first seal must name (None when a missing segment broke the chain),
    ``entry_cycle`` the cycle that seal sealed."""

    def __init__(
        self,
        segment: Segment,
        entry: str | None,
        entry_cycle: int | None,
        key: PublicKey | None,
        sink: FindingSink,
        *,
        recordings: Recordings | None = None,
        recorded: RecordingCheck | None = None,
        keys: KeyChain | None = None,
    ) -> None:
        self.segment = segment
        self.recordings = recordings
        self.recorded = recorded
        """The robot's sealed recording windows, checked as their cycles are read."""
        self.session = segment.session
        self.name = display_name(segment.path)
        self.entry = entry
        self.entry_cycle = entry_cycle
        self.key = key
        self.keys = KeyChain(key) if keys is None else keys
        """The robot's key through the segment: rotations announced in it move it on."""
        self.sink = sink
        self.report = SegmentReporter(sink, self.session.robot_id, self.name, self.session.segment)
        info = segment.info
        self.summary = SegmentSummary(
            path=str(segment.path),
            robot_id=self.session.robot_id,
            number=self.session.segment,
            tier=self.session.tier,
            finished=info.finished,
            recovered=info.recovered,
            live=info.live,
        )
        self.scan = SealScan()
        self.numbering = Numbering(self.report, self.scan, entry_cycle)
        self.checkpoints: list[ReadCheckpoint] = []
        self._checkpoints_seen: dict[int | None, list[RawMessage]] = {}  # chunk -> its own
        self._resumed = False  # the scan stepped over a chunk it could not read
        self._seal_digests = bytearray()  # every sealed cycle's, 32 bytes each, scan order
        self._skipped_before = len(segment.skipped_chunks)
        self.anchor: Anchor | None = None
        self.tail: ChainTail | None = None
        self.findings_before = len(sink.findings)

    def run(self) -> None:
        """Every pass over the segment, then its summary and the notes about it."""
        self._scan_cycles()
        self._take_checkpoints()
        self._report_absent_runs()
        self._report_damaged_chunks()
        self._check_structure()
        self._check_unsealed()
        checkpoints = CheckpointCheck(self.report, self.scan, self.segment, self.keys)
        checkpoints.run(self.checkpoints)
        self.checkpoints_checked(checkpoints)
        self.anchor = checkpoints.anchor
        self._summarise(checkpoints)
        self._notes()

    # Extension points: a check of more than one segment (``robot_chain``) follows what it
    # needs through these instead of a second read of the segment.

    def cycle_read(self, cycle: Cycle) -> None:
        """Called for each cycle the scan reads, in reading order; does nothing here."""

    def checkpoints_checked(self, checkpoints: CheckpointCheck) -> None:
        """Called once the segment's checkpoints are checked, before its summary, so
        findings made here count in the segment's verdict; does nothing here."""

    def _summarise(self, checkpoints: CheckpointCheck) -> None:
        scan = self.scan
        s = self.summary
        s.checkpoints, s.checkpoints_valid = checkpoints.checkpoints, checkpoints.valid
        s.cycles = len(scan.num) + len(scan.unsealed)
        s.cycles_summarised = len(scan.summarised)
        s.cycles_valid = len(scan.num) - len(scan.bad_positions)
        if scan.num:
            s.cycle_range = CycleRange(min(scan.num), max(scan.num), min(scan.t), max(scan.t))
        if scan.last_digest is not None and scan.num:
            self.tail = ChainTail(scan.last_digest, scan.num[-1], scan.t[-1])
        s.last_seal = scan.last_digest
        s.external_resolved = scan.external_ok
        s.external_unresolved = sum(scan.external_unresolved.values())
        s.findings = len(self.sink.findings) - self.findings_before
        s.ok = s.findings == 0

    def _notes(self) -> None:
        """What an investigator should know of this segment that is not tampering."""
        scan, s = self.scan, self.summary
        if scan.summarised:
            first, last = scan.summarised[0], scan.summarised[-1]
            self.report.note(
                "summarised",
                f"{len(scan.summarised)} cycle(s) are warm-tier summaries: summarised (chain "
                "verified, payloads not retained)",
                CycleRange(scan.num[first], scan.num[last], scan.t[first], scan.t[last]),
            )
        if scan.uncited:
            self.report.note(
                "uncovered_sensors",
                f"{scan.uncited} sensor reading(s) are cited by no evidence ref with a digest: "
                "the chain does not cover them",
                s.cycle_range,
            )
        if scan.external_unresolved:
            self._note_external_unresolved()
        if scan.backsteps:
            self._note_clock_backwards()
        if s.recovered:
            self.report.note(
                "recovered",
                "segment has no footer (the robot crashed or the disk "
                "filled); read by a linear scan",
                s.cycle_range,
            )
        elif s.live:
            self.report.note(
                "live",
                "segment is being written (its logger holds the writer lock); read up to "
                "its last complete chunk",
                s.cycle_range,
            )

    def _note_clock_backwards(self) -> None:
        # Not tampering (the seals chain), but the profile forbids it, and it makes a time in
        # this segment name more than one decision: the investigator must be told.
        steps = self.scan.backsteps
        cycle, t_ns, before, before_ns = steps[0]
        more = f" and {len(steps) - 1} more time(s)" if len(steps) > 1 else ""
        self.report.note(
            "clock_backwards",
            f"the robot's clock stepped back within the segment: cycle {cycle} is "
            f"{(before_ns - t_ns) / 1e9:.3f} s earlier than cycle {before}{more} (PROFILE "
            "section 4 forbids it; the chain is intact, but a time here may name more than "
            "one decision)",
            CycleRange(cycle, steps[-1][0], t_ns, steps[-1][1]),
        )

    def _note_external_unresolved(self) -> None:
        s, missing = self.summary, self.scan.external_unresolved
        names = ", ".join(sorted(missing)[:5]) + (" …" if len(missing) > 5 else "")
        self.report.note(
            "external_unresolved",
            f"{sum(missing.values())} evidence ref(s) name external recordings that were not "
            f"given ({names}): not checked, not broken; pass them with --evidence",
            s.cycle_range,
        )

    def _chunk_read(self, offset: int | None, messages: Sequence[RawMessage]) -> None:
        """The scan's read of a chunk: its checkpoints are kept (no cycle holds them)."""
        self._checkpoints_seen[offset] = [m for m in messages if m.topic == TOPIC_CHECKPOINT]

    def _take_checkpoints(self) -> None:
        """The segment's checkpoints in file order, as the scan met them; when the scan did
        not read every chunk in one go (it stepped over one it could not read), from a read
        of their own, as if it had come first. Then the chain heads they name."""
        seen = self._checkpoints_seen
        offsets = self.segment.offsets_in_range(None, None)
        whole = not self._resumed and all(o in seen for o in offsets)
        if whole and (None in seen or not self.segment.loose):
            for message in (*seen.get(None, ()), *(m for o in offsets for m in seen[o])):
                self._add_checkpoint(message)
        else:
            findings = self.sink.findings
            after_scan = len(findings)
            self._read_checkpoints()
            # what this read finds is reported before the scan's findings, as it read first
            moved = findings[after_scan:]
            del findings[after_scan:]
            findings[self.findings_before : self.findings_before] = moved
        self._checkpoints_seen = {}
        self._record_heads()

    def _record_heads(self) -> None:
        """Each seal digest at a cycle a checkpoint names, in reading order."""
        wanted = {c.cycle for _, _, c in self.checkpoints if c is not None}
        heads, digests = self.scan.heads, self._seal_digests
        for position, number in enumerate(self.scan.num):
            if number in wanted:
                heads.setdefault(number, []).append(
                    digests[32 * position : 32 * position + 32].hex()
                )
        self._seal_digests = bytearray()

    def _add_checkpoint(self, message: RawMessage) -> None:
        try:
            checkpoint: Checkpoint | None = decode_checkpoint(message.data)
        except RecordError:
            checkpoint = None
        self.checkpoints.append((message.log_time_ns, message.sequence, checkpoint))

    def _read_checkpoints(self) -> None:
        try:
            for message in iter_checkpoints(self.segment):
                self._add_checkpoint(message)
        except LogReadError as err:  # a damaged file is a finding, not a crash
            self.report.finding("damaged", f"cannot read the segment's checkpoints: {err}")

    def _report_damaged_chunks(self) -> None:
        """A chunk the reader stepped over (fails its CRC, does not decompress) is damage to
        the file, located by the chunk's time range and the cycles read around it."""
        scan = self.scan
        skipped = self.segment.skipped_chunks
        # in file order, as a read of every chunk before the scan would have met them
        found = sorted(skipped[self._skipped_before :], key=lambda chunk: chunk[0])
        for offset, reason in [*skipped[: self._skipped_before], *found]:
            span = self.segment.chunk_span(offset)
            if span is None:
                self.report.finding("damaged", f"part of the segment cannot be read: {reason}")
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
            self.report.finding(
                "damaged",
                f"part of the segment cannot be read: {reason} (t = {start_ns / 1e9:.3f} s .. "
                f"{end_ns / 1e9:.3f} s; {lost}, unverifiable)",
                CycleRange(first, last, start_ns, end_ns),
            )

    def _iter_cycles_resuming(self) -> Iterator[Cycle]:
        """Every readable cycle; a damaged chunk becomes a finding and reading goes on after it."""
        start: int | None = None
        tried: set[int | None] = set()
        last_t: int | None = None
        while start not in tried:
            tried.add(start)
            try:
                for cycle in self.segment.iter_cycles(start_ns=start, chunk_read=self._chunk_read):
                    if last_t is not None and cycle.t_ns <= last_t and start is not None:
                        continue
                    last_t = cycle.t_ns
                    self.cycle_read(cycle)
                    yield cycle
                return
            except LogReadError as err:  # a damaged file is a finding, not a crash
                self._resumed = True
                after = last_t if last_t is not None else -1
                self.report.finding(
                    "damaged",
                    f"part of the segment cannot be read: {err}",
                    CycleRange(None, None, after if after >= 0 else None, None),
                )
                later = [c.start_ns for c in self.segment.chunks() if c.start_ns > after]
                if len(later) < 2:
                    return
                start = later[1]  # skip the chunk that failed (the first one after ``after``)

    def _scan_cycles(self) -> None:
        scan = self.scan
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
            scan.dig.append(digest_prefix(status.seal_digest))
            prev = status.prev or ""
            scan.prev.append(digest_prefix(prev))
            scan.dropped.append(status.dropped)
            scan.link_ok.append(1 if expected is not None and prev == expected else 0)
            if position == 0:
                self._check_entry(prev, cycle)
            expected = status.seal_digest
            scan.last_digest = status.seal_digest
            self._seal_digests += bytes.fromhex(status.seal_digest)
            scan.uncited += status.sensors_uncited
            self._content_findings(status, position)
            recorded = cycle.payloads.get(TOPIC_RECORDING)
            if recorded is not None and self.recorded is not None and status.state in _HELD:
                where = CycleRange(cycle.cycle, cycle.cycle, cycle.t_ns, cycle.t_ns)
                self.recorded.sealed(recorded, where, self.report)

    def _check_entry(self, prev: str, cycle: Cycle) -> None:
        """The first seal against where the chain entered the segment."""
        if self.entry is None:
            self.scan.link_ok[0] = 2  # the previous segment is missing: nothing to compare
        elif self.scan.link_ok[0] and prev != self.session.prev_seal:
            # The chain links up, but the segment's own metadata says otherwise: edited.
            self.report.finding(
                "modified",
                "the segment's trace.session metadata names another previous seal than its "
                "first seal does (the metadata was edited)",
                CycleRange(cycle.cycle, cycle.cycle, cycle.t_ns, cycle.t_ns),
            )

    def _content_findings(self, status: SealStatus, position: int) -> None:
        if status.state == "modified":
            self.scan.bad_positions.add(position)
            self.report.finding(
                "modified",
                f"cycle {status.cycle}: {status.detail}",
                CycleRange(status.cycle, status.cycle, status.t_ns, status.t_ns),
            )
        elif status.state == "summarised":
            self.scan.summarised.append(position)
        if status.evidence_mismatch:
            self.scan.bad_positions.add(position)
            self.report.finding(
                "evidence_mismatch",
                f"cycle {status.cycle}: sensor reading {', '.join(status.evidence_mismatch)} "
                "differs from the digest its evidence ref names",
                CycleRange(status.cycle, status.cycle, status.t_ns, status.t_ns),
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
            self.report.finding(
                "evidence_mismatch",
                f"cycle {status.cycle}: evidence ref into an {EXTERNAL_RECORDING} does not "
                f"resolve: {'; '.join(broken)}",
                CycleRange(status.cycle, status.cycle, status.t_ns, status.t_ns),
            )

    def _extend_absent_run(self, check: ExternalCheck, status: SealStatus) -> None:
        # A recording cut short loses every message after the cut: one finding for the run
        # says so, where one per cycle would bury it.
        at = (status.cycle, status.t_ns)
        run = self.scan.absent_open.get(check.recording)
        if run is None:
            self.scan.absent_open[check.recording] = AbsentRun(
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
                    f"an evidence ref names a message that {EXTERNAL_RECORDING} {run.recording} "
                    f"does not hold: {run.detail}"
                )
            else:
                # only a run says something about the recording as a whole
                what = (
                    f"{run.refs} evidence refs name messages that {EXTERNAL_RECORDING} "
                    f"{run.recording} does not hold (the first: {run.detail}); a run of them "
                    "means the recording was cut short or those messages removed"
                )
            self.report.finding(
                "evidence_mismatch", f"{where}: {what}", CycleRange(first, last, first_ns, last_ns)
            )
        scan.absent_runs, scan.absent_open = [], {}

    # --- the chain inside the segment ------------------------------------------------------

    def _check_structure(self) -> None:
        scan = self.scan
        n = len(scan.num)
        if n == 0:
            return
        if all(ok for ok in scan.link_ok):
            self.numbering.check(range(n))
            return
        ChainOrder(
            self.report,
            scan,
            self.numbering,
            entry=self.entry,
            first_cycle=self.session.first_cycle,
        ).classify()

    def _check_unsealed(self) -> None:
        scan = self.scan
        n = len(scan.num)
        for position, number, t in scan.unsealed:
            if position == n and (self.summary.recovered or self.summary.live):
                self.report.note(
                    "unanchored",
                    f"cycle {number} was being written when the robot "
                    "stopped: layer messages without a seal",
                    CycleRange(number, number, t, t),
                )
            else:
                self.report.finding(
                    "unsealed",
                    f"cycle {number}: layer messages without a seal "
                    "(inserted, or its seal was removed)",
                    CycleRange(number, number, t, t),
                )
