"""``doctor``: does a log follow the TRACE profile? The checker a writer in any language runs.

Each segment file is checked at two levels: its MCAP records and messages against every rule
of ``schemas/PROFILE.md`` that can be read off the file (``structure``, ``content``), and its
seals, chain, checkpoints, drops and evidence digests by the one verifier
(``trace_runtime.verification``), whose findings are mapped to the rules they break. Every
problem names its rule, the PROFILE section, MUST or SHOULD, and where it is (cycle, file
offset). A log conforms when no MUST is broken; SHOULD deviations are notes.

A log root of several robots is checked whole, or cut to some of its robots
(``selection.Selection``, as every investigating command selects): then only their segment
files are checked, and only their chains verified.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from pathlib import Path

from trace_audit.doctor.rules import RULES, DoctorReport, Problem, Rule, SegmentDoctor
from trace_audit.doctor.structure import check_structure
from trace_audit.evidence import open_recordings, recordings_for
from trace_audit.selection import Selection
from trace_runtime.errors import LogReadError
from trace_runtime.reading.logset import Log, open_log
from trace_runtime.reading.recordings import Recordings
from trace_runtime.reading.segment_files import find_segment_files
from trace_runtime.segment_names import parse_segment_name
from trace_runtime.session import SessionInfo
from trace_runtime.verification import Finding, is_external_evidence, verify

__all__ = ["RULES", "DoctorReport", "Problem", "Rule", "SegmentDoctor", "doctor_log"]

# verify's finding kinds -> the rule each breaks (PROFILE sections 4-8, 11)
_FINDING_RULES = {
    "modified": "seal-chain",
    "missing": "seal-chain",
    "inserted": "seal-chain",
    "reordered": "seal-chain",
    "missing_segment": "seal-chain",
    "undeclared_gap": "declared-drops",
    "truncated": "checkpoint",
    "checkpoint_mismatch": "checkpoint",
    "bad_signature": "checkpoint",
    "key_mismatch": "checkpoint",
    "unsigned_checkpoint": "checkpoint",
    "tree_mismatch": "checkpoint",
    "damaged": "readable",
}
# "unsealed" is left out: the content checks report layer messages without a seal (the
# same rule), located by the file offset the verifier does not know.
_NOTE_RULES = {"external_unresolved": "external-given", "no_checkpoints": "checkpoint-cadence"}


def doctor_log(
    path: str | Path,
    *,
    robots: Sequence[str] = (),
    evidence: Sequence[str | Path] = (),
    progress: Callable[[int, int], None] | None = None,
) -> DoctorReport:
    """Check a segment file, or every segment under a directory, against the profile.

    ``robots``: only these robots' segments (``Selection.of``: a robot the log does not
    hold is a ``UsageError`` naming those it does, exit 2); none means every file.
    ``evidence``: external recordings (MCAP files or rosbag2 directories) that evidence refs
    name; without them such refs are a note (not checked), never a broken rule.
    ``progress(bytes_done, bytes_total)`` is called as the files are walked.
    Raises ``LogReadError`` (exit 3) when the path is missing, holds no MCAP file, or a file
    is not MCAP at all.
    """
    root = Path(path)
    if not root.exists():
        raise LogReadError(str(root), "no such file or directory")
    files = find_segment_files(root)
    if not files:
        raise LogReadError(str(root), "no .mcap segment here")
    selected: Log | None = None
    if robots:
        # The reader must know whose each file is; a log it cannot open at all has no
        # robots to choose among (doctor without --robot explains such files).
        selected = Selection(robots=tuple(robots)).of(open_log(root))
        files = _files_in(selected, files)
    given = open_recordings(evidence)
    report = DoctorReport(str(root))
    by_name: dict[str, SegmentDoctor] = {}
    total, done = sum(f.stat().st_size for f in files), 0
    for file in files:
        segment = SegmentDoctor(str(file))
        step = None if progress is None else functools.partial(_step, progress, done, total)
        segment.robot = _robot(file, check_structure(file, segment, progress=step))
        report.segments.append(segment)
        by_name[file.name] = segment
        done += file.stat().st_size
        if progress is not None:
            progress(done, total)
    recordings = _verify_into(root, selected, report, by_name, evidence=evidence, given=given)
    report.evidence = recordings.names if recordings else []
    report.conforms = all(s.conforms for s in report.segments)
    return report


def _files_in(log: Log, files: Sequence[Path]) -> list[Path]:
    """``files`` (in their order) that ``log`` reads, shadows, or could not open."""
    held = {s.path for s in (*log.segments, *log.shadowed)} | {p.path for p in log.problems}
    return [f for f in files if f in held]


def _robot(file: Path, session: SessionInfo | None) -> str | None:
    """Whose segment ``file`` is: its session says; when it has none, its name."""
    if session is not None:
        return session.robot_id
    named = parse_segment_name(file.name)
    return None if named is None else named[0]


def _step(progress: Callable[[int, int], None], before: int, total: int, offset: int) -> None:
    progress(before + offset, total)


def _verify_into(
    root: Path,
    log: Log | None,
    report: DoctorReport,
    by_name: dict[str, SegmentDoctor],
    *,
    evidence: Sequence[str | Path],
    given: Recordings | None,
) -> Recordings | None:
    """Run the verifier over the log (``log``, the robots selected; else the whole of
    ``root``) with the recordings it declares and those given, and file its findings under
    their segments; the recordings used."""
    recordings = given
    try:
        whole = open_log(root) if log is None else log
        recordings = recordings_for(whole, evidence)
        verified = verify(whole, recordings=recordings)
    except LogReadError as err:
        # The reader refuses what the structure checks may have let through (or explained).
        target = report.segments[0] if len(report.segments) == 1 else None
        for segment in [target] if target else report.segments:
            if segment is not None and segment.conforms:
                segment.add("readable", f"the reference reader refuses the log: {err.reason}")
        return recordings
    for finding in verified.findings:
        if finding.kind == "unsealed":
            continue
        rule = _FINDING_RULES.get(finding.kind)
        if finding.kind == "evidence_mismatch":
            # in-log refs are checked (with their window) by the content checks; a ref into
            # an external recording breaks §11 whether its message differs or is not there
            # (verify already makes a run of absent ones one finding, so one problem)
            if not is_external_evidence(finding):
                continue
            rule = "external-digest"
        _file(finding, rule or "seal-chain", report, by_name)
    for note in verified.notes:
        rule = _NOTE_RULES.get(note.kind)
        if rule is not None:
            _file(note, rule, report, by_name)
    return recordings


def _file(
    finding: Finding, rule: str, report: DoctorReport, by_name: dict[str, SegmentDoctor]
) -> None:
    name = finding.segment.rsplit("/", 1)[-1]
    segment = by_name.get(name) or report.segments[0]
    segment.add(
        rule, finding.message, cycle=finding.where.first_cycle, last_cycle=finding.where.last_cycle
    )
