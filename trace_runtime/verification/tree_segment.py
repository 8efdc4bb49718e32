"""One segment's check that also follows the robot's Merkle tree (profile 1.2), for the walk
along a robot's chain (``robot_chain``)."""

from __future__ import annotations

from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.merkle import CompactRange, leaf_hash
from trace_runtime.tlog.rotation import KeyChain
from trace_runtime.verification.checkpoint_check import CheckpointCheck, TreeCheck
from trace_runtime.verification.recording_check import RecordingCheck
from trace_runtime.verification.segment_check import SegmentCheck
from trace_runtime.verification.sink import FindingSink

__all__ = ["TreeSegmentCheck"]


class TreeSegmentCheck(SegmentCheck):
    """A segment's check that also follows the robot's Merkle tree: it keeps each seal's
    leaf hash as the cycles are read (one pass, no second read) and checks the segment's 1.2
    checkpoints against the tree (``TreeCheck``) before the segment is summarised, so its
    findings count in the segment's verdict and a checkpoint with a wrong tree vouches for
    nothing. ``exit_tree`` is the tree after the segment's last seal."""

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
        entry_tree: CompactRange | None = None,
        keys: KeyChain | None = None,
    ) -> None:
        super().__init__(
            segment,
            entry,
            entry_cycle,
            key,
            sink,
            recordings=recordings,
            recorded=recorded,
            keys=keys,
        )
        self.entry_tree = entry_tree
        self.exit_tree: CompactRange | None = None
        self.leaves: list[bytes] = []

    def cycle_read(self, cycle: Cycle) -> None:
        data = cycle.payloads.get(TOPIC_SEAL)
        if data is not None:
            self.leaves.append(leaf_hash(data))

    def checkpoints_checked(self, checkpoints: CheckpointCheck) -> None:
        tree = TreeCheck(self.report, self.scan, self.key, self.leaves, self.entry_tree)
        tree.run(self.checkpoints, checkpoints)
        self.exit_tree = tree.exit
        self.leaves = []  # the tree keeps what it needs
