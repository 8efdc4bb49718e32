"""Where a robot's chain goes on when its logger starts on a log root that already holds
some of its segments: the next cycle number, the seal to link to, the next segment number.

The segments are the log's own (``segment_files.robot_segment_files``), and of a segment found in
several copies (one mid-compaction in two tiers, a copy cut short beside its original) the
copy every reader reads comes first (``copies.best_copy_first``). It runs at logger start-up, so
it reads only what it needs: names, then the newest segment's last seal (from its end).

The robot's Merkle tree (profile 1.2) goes on too (``resume_tree``): from the newest
checkpoint's compact range plus the seals after it (a crashed segment has some), or, when the
chain has no 1.2 checkpoint yet, from all its seals, once.

Two more answers for a robot that goes on where it stopped: the time and clock of its last
cycle on disk (``resume_time``, for a simulated robot whose clock should go on too), and the
key its newest signed checkpoint hands on (``rotated_to``, for a logger told to rotate to a
key its chain may already have announced, ``LoggerConfig.next_key``).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

from trace_runtime.errors import TraceError
from trace_runtime.reading.chain_tree import tree_through
from trace_runtime.reading.copies import best_copy_first
from trace_runtime.reading.logset import open_segments
from trace_runtime.reading.reader import Segment, last_seal
from trace_runtime.reading.segment_files import robot_segment_files
from trace_runtime.records import GENESIS, Checkpoint
from trace_runtime.tlog.checkpoints import check_checkpoint, decode_checkpoint, iter_checkpoints
from trace_runtime.tlog.keys import PublicKey, Signer
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.rotation import check_announcement

__all__ = ["ResumePoint", "resume_point", "resume_time", "resume_tree", "rotated_to"]


class ResumePoint(NamedTuple):
    """Where the robot's chain continues."""

    next_cycle: int
    prev_seal: str
    """The digest of the last seal on disk (``GENESIS`` when there is none)."""
    next_segment: int


FRESH = ResumePoint(0, GENESIS, 0)
"""A robot with no segment in the root yet."""


def resume_point(root: Path, robot_id: str) -> ResumePoint:
    """The resume point after the robot's newest segment in ``root``.

    The highest segment number wins, whatever tier it lives in. The chain continues from the
    newest seal on disk: a segment a crash left without any seal (killed before its first
    write), or one that cannot be read, is passed over for an older one, so the chain does
    not restart.
    """
    numbered = robot_segment_files(root, robot_id)
    if not numbered:
        return FRESH
    next_segment = max(numbered) + 1
    for number in sorted(numbered, reverse=True):
        for copy in _copies_best_first(numbered[number]):
            found = last_seal(copy)
            if found is not None:
                seal, seal_digest = found
                return ResumePoint(seal.cycle + 1, seal_digest, next_segment)
    return ResumePoint(0, GENESIS, next_segment)


def resume_tree(root: Path, robot_id: str, prev_seal: str) -> CompactRange | None:
    """The robot's tree through the seal ``prev_seal`` names (``ResumePoint.prev_seal``):
    the newest 1.2 checkpoint's ``range`` before it plus the seals after that checkpoint,
    in its segment and any later ones (``chain_tree.tree_through``). None when the chain on
    disk cannot be followed to that seal; never raises (a robot starts logging regardless)."""
    if prev_seal == GENESIS:
        return CompactRange()
    try:
        return tree_through(root, robot_id, prev_seal)
    except (TraceError, OSError):
        return None


def resume_time(root: Path, robot_id: str) -> tuple[int, str] | None:
    """The time (ns) of the robot's newest seal on disk and the clock of the segment that
    holds it; None for a robot with no readable seal in ``root``."""
    for files in _newest_first(root, robot_id):
        for copy in _copies_best_first(files):
            try:
                segment = copy if isinstance(copy, Segment) else Segment(copy)
            except TraceError:
                continue
            found = last_seal(segment)
            if found is not None:
                return found[0].t_ns, segment.session.clock
    return None


def rotated_to(root: Path, robot_id: str, old: Signer, new: PublicKey) -> bool:
    """Whether the robot's chain in ``root`` already hands on to ``new``: its newest
    checkpoint signed by ``old`` or ``new`` is ``new``'s, or is ``old``'s and announces
    ``new`` (profile 1.5). Checkpoints neither key signed (unsigned, damaged, planted under
    another key) are passed over, as damage is by the chain's resume."""
    old_public = getattr(old, "public_key", None)
    for files in _newest_first(root, robot_id):
        for copy in _copies_best_first(files):
            try:
                segment = copy if isinstance(copy, Segment) else Segment(copy)
                messages = list(iter_checkpoints(segment))
            except TraceError:
                continue
            for message in reversed(messages):
                try:
                    checkpoint = decode_checkpoint(message.data)
                except TraceError:
                    continue
                if check_checkpoint(checkpoint, new) == "valid":
                    return True
                if _signed_by(checkpoint, old, old_public):
                    if not isinstance(old_public, PublicKey):
                        return False  # a signer that cannot check its own announcement
                    announced = check_announcement(checkpoint, old_public)[1]
                    return announced is not None and announced.key_id == new.key_id
    return False


def _signed_by(checkpoint: Checkpoint, old: Signer, public: object) -> bool:
    if isinstance(public, PublicKey):
        return check_checkpoint(checkpoint, public) == "valid"
    # A Signer without its public key (an HSM behind the protocol): by its key id.
    return checkpoint.signature is not None and checkpoint.key_id == old.key_id


def _newest_first(root: Path, robot_id: str) -> list[list[Path]]:
    numbered = robot_segment_files(root, robot_id)
    return [numbered[n] for n in sorted(numbered, reverse=True)]


def _copies_best_first(files: list[Path]) -> list[Path] | list[Segment]:
    """One segment's files in the order readers prefer them; a single file is not opened
    here (``last_seal`` opens it), several are opened to be ranked."""
    if len(files) == 1:
        return files
    segments, _unreadable = open_segments(sorted(files))
    return best_copy_first(segments) if segments else []
