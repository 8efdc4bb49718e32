"""What ``verify`` reports: the kinds of finding and note, a located ``Finding``, and the
summaries of a segment, a robot's chain and the whole log.

Every location is a ``gaps.CycleRange`` (cycles and times, any end unknown), inlined in JSON
as the ``first_cycle``/``last_cycle``/``start_ns``/``end_ns`` keys. A finding whose message
names an external recording (``EXTERNAL_RECORDING``) is about evidence outside the log.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from trace_runtime.gaps import JSON_INLINE, NOWHERE, CycleRange
from trace_runtime.session import TIERS
from trace_runtime.tlog.rotation import KeyRotation

__all__ = [
    "EXTERNAL_RECORDING",
    "KIND_WORDS",
    "Finding",
    "FindingKind",
    "NoteKind",
    "RobotSummary",
    "SegmentSummary",
    "VerifyReport",
    "describe_numbers",
    "display_name",
    "is_external_evidence",
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
    "tree_mismatch",
    "truncated_tail",
    "fork",
    "recording_modified",
]
"""What a finding says happened; every kind makes ``verify`` exit 1. ``tree_mismatch``: a
profile 1.2 checkpoint states another Merkle tree (size, root, range) than the robot's seals
give, or its C2SP note states another tree than the checkpoint. ``truncated_tail`` and
``fork`` come from a witness (``verify --witness``): the robot's tree ends before the size a
witness cosigned, or differs from it at that size. ``recording_modified``: a message of a
recording the robot cites was changed, removed or added in a window its chain sealed
(profile 1.4)."""

NoteKind = Literal[
    "declared_gap",
    "summarised",
    "unanchored",
    "recovered",
    "live",
    "signatures_unchecked",
    "chain_start",
    "duplicate_segment",
    "skipped_file",
    "uncovered_sensors",
    "no_checkpoints",
    "external_unresolved",
    "clock_backwards",
    "clock_restart",
    "clock_step",
    "recording_gap",
    "recording_unchecked",
    "recording_unsealed",
]
"""Things an investigator should know that are not tampering. ``recording_gap``: the logger
declared a recording absent, stalled or unreadable; ``recording_unchecked``: sealed windows of
a recording that is not here; ``recording_unsealed``: recorded messages after the last window
the chain sealed (written after the robot's last cycle, or within the sealing lag)."""

KIND_WORDS: dict[str, str] = {
    # findings
    "modified": "a record changed after it was sealed",
    "evidence_mismatch": "a sensor reading differs from the one the decision cited",
    "missing": "sealed cycles missing",
    "inserted": "cycles inserted",
    "reordered": "cycles out of order",
    "unsealed": "cycles without a seal",
    "undeclared_gap": "cycles missing that the logger never declared dropped",
    "truncated": "a segment cut short",
    "missing_segment": "a segment missing",
    "checkpoint_mismatch": "a checkpoint disagrees with the seals",
    "bad_signature": "a signature that does not verify",
    "key_mismatch": "signed with another key",
    "unsigned_checkpoint": "a checkpoint without a signature",
    "damaged": "damaged data",
    "tree_mismatch": "a checkpoint states another tree than the seals give",
    "truncated_tail": "the log ends before what a witness cosigned",
    "fork": "the log differs from what a witness cosigned",
    "recording_modified": "a recording changed after it was sealed",
    # notes
    "declared_gap": "cycles the logger declared dropped",
    "summarised": "cycles kept as summaries (warm tier)",
    "unanchored": "cycles no checkpoint vouches for",
    "recovered": "recovered from an unfinished segment",
    "live": "a segment still being written",
    "signatures_unchecked": "signatures not checked",
    "chain_start": "where the chain starts",
    "duplicate_segment": "a segment held twice",
    "skipped_file": "a file left out",
    "uncovered_sensors": "sensor readings no seal covers",
    "no_checkpoints": "no checkpoint",
    "external_unresolved": "evidence in a recording not read",
    "clock_backwards": "the clock went back",
    "clock_restart": "the clock restarted",
    "clock_step": "the clock was stepped",
    "recording_gap": "a recording the logger declared missing",
    "recording_unchecked": "a recording not checked",
    "recording_unsealed": "recorded messages no seal covers yet",
}
"""Each finding and note kind in an investigator's words, for pages people read (the
report); the kinds themselves stay the names scripts match (JSON, data attributes)."""

_INLINE = {JSON_INLINE: True}


@dataclass(frozen=True, slots=True, kw_only=True)
class Finding:
    """One located problem (or note): what, where in the log, which cycles and times."""

    kind: FindingKind | NoteKind
    message: str
    robot_id: str = ""
    segment: str = ""
    segment_no: int | None = None
    where: CycleRange = field(default=NOWHERE, metadata=_INLINE)

    def covers(self, cycle: int) -> bool:
        """True when ``cycle`` lies in the finding's cycle range."""
        return cycle in self.where


@dataclass(slots=True)
class SegmentSummary:
    """What verify saw in one segment file."""

    path: str
    robot_id: str
    number: int
    tier: str
    finished: bool
    recovered: bool
    live: bool = False
    """No footer yet because its logger is writing it (not a crash)."""
    cycles: int = 0
    cycles_valid: int = 0
    cycles_summarised: int = 0
    checkpoints: int = 0
    checkpoints_valid: int = 0
    cycle_range: CycleRange = field(default=NOWHERE, metadata=_INLINE)
    """The sealed cycles read, and their times."""
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
    cycle_range: CycleRange = field(default=NOWHERE, metadata=_INLINE)
    """The validated range: every sealed cycle of the segments read first."""
    anchored_cycle: int | None = None
    """Last cycle a matching (and, with a key, validly signed) checkpoint vouches for."""
    anchored_ns: int | None = None
    unanchored_cycles: int = 0
    """Cycles after ``anchored_cycle``: chained, but no checkpoint vouches for them yet."""
    clock: str = "system"
    """The clock behind the robot's times (``SessionInfo.clock``), for showing them."""
    recording_windows: int = 0
    """Windows of the robot's recordings its chain sealed (profile 1.4)."""
    recording_messages: int = 0
    """Recorded messages those windows seal, cited or not."""
    recording_checked: int = 0
    """Of those windows, the ones checked against a recording that is here."""
    announced_keys: list[str] = field(default_factory=list)
    """The keys the robot's chain announced and the check followed (profile 1.5: verifier
    keys, in chain order); empty without rotations, or without a key to follow them from."""
    key_rotations: list[KeyRotation] = field(default_factory=list)
    """The same rotations, each with the announcing checkpoint's cycle and the key ids
    (SHA-256, as ``keygen`` and ``verify`` show them) of the keys rotated from and to."""


@dataclass(slots=True)
class VerifyReport:
    """The result of ``verify``; ``ok`` is False when there is any finding."""

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
    recording_windows: int = 0
    """Sealed windows of the robots' recordings, every robot's summed (``RobotSummary``)."""
    recording_messages: int = 0
    recording_checked: int = 0
    cycle_range: CycleRange = field(default=NOWHERE, metadata=_INLINE)
    """Every robot's validated range merged."""
    ok: bool = True
    """No finding: every cycle read verifies (notes may still say what is not covered)."""


EXTERNAL_RECORDING = "external recording"
"""Named in the message of every finding about a ref into an external recording (changed
or absent), so ``is_external_evidence`` can tell them from in-log refs."""


def is_external_evidence(finding: Finding) -> bool:
    """True for an evidence mismatch of a ref into an external recording (PROFILE section 11),
    whether the message it names differs or is not there."""
    return finding.kind == "evidence_mismatch" and EXTERNAL_RECORDING in finding.message


def display_name(path: Path) -> str:
    """How findings name a segment file: ``tier/name`` inside a tier folder, else its name."""
    parts = path.parts
    return "/".join(parts[-2:]) if len(parts) >= 2 and parts[-2] in TIERS else path.name


def describe_numbers(numbers: list[int]) -> str:
    """Cycle or segment numbers as a finding names them: ``a..b`` when consecutive."""
    if len(numbers) == 1:
        return str(numbers[0])
    if numbers == list(range(numbers[0], numbers[-1] + 1)):
        return f"{numbers[0]}..{numbers[-1]}"
    return ", ".join(str(n) for n in numbers[:8]) + (", …" if len(numbers) > 8 else "")
