"""``verify``: is this log what the robot wrote, all of it, in order?

The investigator's thin front on ``trace_runtime.verification`` (which owns every rule of
the verdict): ``verify_log`` takes what an investigator has at hand (a path, external
recordings to resolve evidence refs in), opens the log through the one owner of multi-file
logs (``trace_runtime.logset.open_log``: which copy of a segment is read, which files could
not be read) and the recordings (``trace_audit.evidence``), and hands both to
``trace_runtime.verification.verify``. Retention in the runtime deletes only what that
same verification finds clean. For one decision (``explain``) the check is
``trace_runtime.seal_check.verify_cycle``. See docs/integrity.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from pathlib import Path

from trace_audit.evidence import open_recordings
from trace_audit.selection import Selection
from trace_runtime.keys import PublicKey
from trace_runtime.logset import open_log
from trace_runtime.verification import (
    Finding,
    FindingKind,
    NoteKind,
    RobotSummary,
    SegmentSummary,
    VerifyReport,
    verify,
)

__all__ = [
    "Finding",
    "FindingKind",
    "NoteKind",
    "RobotSummary",
    "SegmentSummary",
    "VerifyReport",
    "verify_log",
]


def verify_log(
    path: str | Path,
    *,
    key: PublicKey | None = None,
    evidence: Sequence[str | Path] = (),
    executor: Executor | None = None,
    robots: Sequence[str] = (),
) -> VerifyReport:
    """Verify a segment file, a directory of segments or a log root; never raises on tampering.

    ``evidence``: external recordings (MCAP files, rosbag2 directories) that evidence refs
    name: each such ref is resolved and its digest checked there (a mismatch is a finding);
    refs into recordings not given are counted as unresolved (a note), not as broken.
    Raises ``LogReadError`` only when nothing readable is there (exit 3 at the CLI); a damaged
    segment inside a root is a finding. ``robots``: only these robots' chains
    (``selection.Selection``).
    """
    recordings = open_recordings(evidence)
    log = Selection(tuple(robots)).of(open_log(path))
    return verify(log, key=key, recordings=recordings, executor=executor)
