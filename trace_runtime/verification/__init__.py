"""Is this log what the robot wrote, all of it, in order? The one verification of a log.

In the spirit of CloudTrail's ``validate-logs``: every cycle is checked against its seal
(``seal_check.verify_cycle``), every seal against the previous one (across segments and
restarts), every checkpoint's head against the chain and its signature against the robot's
public key. Problems are located (robot, segment, cycle range, time range) and classified:

- tampering: a modified record, missing / inserted / reordered cycles, a finished segment cut
  short, a missing segment, a checkpoint that does not match the chain, a bad signature,
  another key, an unsigned checkpoint when a key was expected;
- not tampering, reported as notes: cycles the logger declared dropped (``seal.dropped``),
  warm-tier summary cycles (chain verified, payloads not retained), and the tail of a crashed
  segment that no checkpoint vouches for yet (it still chain-verifies up to the cut).

``verify(log, key=)`` returns a ``VerifyReport`` whose ``segments`` say, per file, whether it
verified. The investigator's ``trace-audit verify`` and the runtime's retention (which
deletes only segments that verify) both stand on it. See docs/integrity.md.

The package, from the top down: ``robot_chain`` (the whole log: each robot's chain across
its segments, the fan-out over workers), ``segment_check`` (one segment), and beneath it
``checkpoint_check``, ``reorder`` (broken links explained), ``numbering`` (declared drops),
``scan`` (what one pass over the seals gathers), ``sink`` (where findings go) and
``report`` (the result types).
"""

from __future__ import annotations

from trace_runtime.verification.report import (
    Finding,
    FindingKind,
    NoteKind,
    RobotSummary,
    SegmentSummary,
    VerifyReport,
    is_external_evidence,
)
from trace_runtime.verification.robot_chain import problem_finding, verify

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
