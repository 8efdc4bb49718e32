"""A segment's checkpoints against its chain: each head must be a seal the log holds, each
count the sealed cycles it holds, each signature the robot's key; a segment its logger closed
must end with its closing checkpoint, and nothing may follow it.

A checkpoint that matches (and, with a key, verifies) is an ``Anchor``: it vouches for every
cycle up to it.

Profile 1.2 checkpoints also state the robot's Merkle tree through their head seal; the
``TreeCheck`` recomputes it from the seals (a compact range carried along the robot's chain)
and checks each one's size, root, range and C2SP note.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

from trace_runtime.gaps import CycleRange
from trace_runtime.reading.chain_tree import checkpoint_range, has_tree
from trace_runtime.reading.reader import Segment
from trace_runtime.records import Checkpoint
from trace_runtime.session import TIER_METADATA
from trace_runtime.tlog.checkpoints import CheckpointState, NoteState, check_checkpoint, check_note
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.rotation import KeyChain
from trace_runtime.verification.report import FindingKind
from trace_runtime.verification.scan import Anchor, SealScan
from trace_runtime.verification.sink import SegmentReporter

__all__ = ["CheckpointCheck", "ReadCheckpoint", "TreeCheck"]

ReadCheckpoint = tuple[int, int, Checkpoint | None]
"""A checkpoint message as read: (log time, MCAP sequence, the record or None if invalid)."""

_SIGNATURE_PROBLEMS = {
    "bad_signature": "its signature does not verify with the given key",
    "unsigned": "it is not signed, but a key was given",
}


@dataclass(slots=True)
class CheckpointCheck:
    """Checks one segment's checkpoints against its scan; counts them and finds the anchor."""

    report: SegmentReporter
    scan: SealScan
    segment: Segment
    keys: KeyChain
    """The key the robot's checkpoints are signed with here, followed through the key
    rotations they announce (profile 1.5)."""
    checkpoints: int = 0
    valid: int = 0
    anchor: Anchor | None = None
    vouching: list[Checkpoint] = field(default_factory=list)
    """The checkpoints that matched (and verified): each an anchor candidate."""
    key_of: dict[int, PublicKey] = field(default_factory=dict)
    """The key each vouching checkpoint (by ``id``) was checked with: its note's key."""

    def run(self, read: list[ReadCheckpoint]) -> None:
        """Check every checkpoint read from the segment, then how the segment ends."""
        scan = self.scan
        last_cycle = scan.num[-1] if scan.num else None
        is_sorted = all(scan.num[i] < scan.num[i + 1] for i in range(len(scan.num) - 1))
        window_start = self.segment.session.first_cycle
        final_seen: Checkpoint | None = None
        for log_time, sequence, checkpoint in read:
            self.checkpoints += 1
            if checkpoint is None:
                self.report.finding(
                    "modified",
                    f"the checkpoint after cycle {sequence} is not a valid checkpoint record",
                    CycleRange(sequence, sequence, log_time, log_time),
                )
                continue
            c = checkpoint
            # Located by what it claims and by where it sits (its MCAP sequence is its cycle).
            where = CycleRange(min(window_start, c.cycle), max(c.cycle, sequence), None, log_time)
            if self._one(c, where, window_start, last_cycle, is_sorted=is_sorted):
                window_start = c.cycle + 1
            if c.final:
                final_seen = c
        # A segment its logger closed ends with its closing checkpoint; one without a summary
        # (a crash) cannot have one. Compacted tiers carry checkpoints over with the cycles.
        if _closed_by_logger(self.segment) and last_cycle is not None:
            self._check_end(read, final_seen, last_cycle)

    def _one(
        self,
        c: Checkpoint,
        where: CycleRange,
        window_start: int,
        last_cycle: int | None,
        *,
        is_sorted: bool,
    ) -> bool:
        """Check one checkpoint record; True when it matches the chain and vouches for it."""
        scan = self.scan
        problems = self._checkpoint_problems(c, last_cycle, is_sorted)
        key = self.keys.key
        state: CheckpointState = check_checkpoint(c, key)
        if problems:
            kind: FindingKind = problems[0][0]
            located = where
            if kind == "truncated" and last_cycle is not None:
                located = CycleRange(last_cycle + 1, c.cycle, scan.t[-1], c.t_ns)
            self.report.finding(
                kind,
                f"checkpoint at cycle {c.cycle}: " + "; ".join(p[1] for p in problems),
                located,
            )
        if state in ("bad_signature", "key_mismatch", "unsigned"):
            message = (
                self.keys.why_not(c.key_id)
                if state == "key_mismatch"
                else _SIGNATURE_PROBLEMS[state]
            )
            self.report.finding(
                "unsigned_checkpoint" if state == "unsigned" else state,
                f"checkpoint at cycle {c.cycle}: {message}; "
                f"cycles {window_start}..{c.cycle} are not vouched for",
                where,
            )
        if problems or state not in ("valid", "unchecked"):
            return False
        if key is not None and not self._follow_rotation(c, key, where):
            return False
        self.valid += 1
        self.vouching.append(c)
        if key is not None:
            self.key_of[id(c)] = key
        if self.anchor is None or c.cycle >= self.anchor.cycle:
            self.anchor = Anchor(c.cycle, c.t_ns)
        return True

    def _follow_rotation(self, c: Checkpoint, key: PublicKey, where: CycleRange) -> bool:
        """A verified checkpoint that announces the next key (profile 1.5): from here on
        that key signs. False when the announcement does not verify: it vouches for nothing
        and the key stays."""
        state = self.keys.follow(c, key)
        if state in ("none", "valid"):
            return True
        why = "does not verify" if state == "bad_signature" else "is malformed"
        self.report.finding(
            "bad_signature",
            f"checkpoint at cycle {c.cycle}: its announcement of the next key {why}",
            where,
        )
        return False

    def _check_end(
        self, read: list[ReadCheckpoint], final_seen: Checkpoint | None, last_cycle: int
    ) -> None:
        """A closed segment: its closing checkpoint is there and nothing follows it."""
        scan = self.scan
        last_t = scan.t[-1]
        if not read:
            self._no_checkpoints(last_cycle, last_t)
        elif final_seen is None:
            anchored = f"cycle {self.anchor.cycle}" if self.anchor else "none"
            self.report.finding(
                "truncated",
                "the segment was finished but has no closing checkpoint: its end was cut "
                f"after cycle {last_cycle} (last checkpoint: {anchored})",
                CycleRange(last_cycle + 1, None, last_t, None),
            )
        elif final_seen.cycle < last_cycle:
            after = [i for i in range(len(scan.num)) if scan.num[i] > final_seen.cycle]
            self.report.finding(
                "inserted",
                f"cycles after the closing checkpoint (cycle {final_seen.cycle}): "
                f"{len(after)} cycle(s) appended",
                CycleRange(final_seen.cycle + 1, last_cycle, final_seen.t_ns, last_t),
            )
            scan.bad_positions.update(after)

    def _no_checkpoints(self, last_cycle: int, last_t: int | None) -> None:
        """A closed segment without a single checkpoint: its writer skips PROFILE §6's SHOULD.

        Nothing shows that its end was cut (a writer that checkpoints at all closes with a
        final one, so a missing final among others is ``truncated``), but nothing vouches for
        its end either. With a key the investigator expects signatures: then it is a finding.
        """
        first_t = min(self.scan.t) if self.scan.t else None
        first_cycle = self.segment.session.first_cycle
        span = CycleRange(first_cycle, last_cycle, first_t, last_t)
        if self.keys.key is not None:
            self.report.finding(
                "unsigned_checkpoint",
                "a key was given but the segment holds no checkpoint: no signature vouches "
                f"for cycles {first_cycle}..{last_cycle}",
                span,
            )
            return
        self.report.note(
            "no_checkpoints",
            "end not anchored: no final checkpoint (the segment holds no checkpoints at all; "
            "its writer skips the SHOULD of PROFILE §6, so a cut end could not be told)",
            CycleRange(last_cycle, last_cycle, last_t, last_t),
        )

    def _checkpoint_problems(
        self, c: Checkpoint, last_cycle: int | None, is_sorted: bool
    ) -> list[tuple[FindingKind, str]]:
        problems: list[tuple[FindingKind, str]] = []
        session = self.segment.session
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


_NOTE_PROBLEMS: dict[NoteState, tuple[FindingKind, str]] = {
    "mismatch": ("tree_mismatch", "its C2SP note states another tree than the checkpoint"),
    "bad_signature": ("bad_signature", "its C2SP note does not verify"),
    "key_mismatch": ("key_mismatch", "its C2SP note is not signed by the given key"),
    "unsigned": ("unsigned_checkpoint", "its tree is not signed (no C2SP note)"),
}


class TreeCheck:
    """One segment's 1.2 checkpoints against the robot's Merkle tree (PROFILE §6).

    ``leaves`` are the leaf hashes of the segment's seals in reading order (one per position
    of ``scan.num``); ``entry`` the tree before the segment's first seal, None when it is not
    known (the log starts after the robot's genesis, a segment is missing): then the first
    1.2 checkpoint whose range agrees with its own root is taken as the tree at its head, as
    a restarted logger takes it. The tree is followed only along a chain that otherwise
    verifies (in order, nothing damaged or modified): there the other findings say what is
    wrong, and the tree is taken up again at the next checkpoint. ``exit`` is the tree after
    the segment's last seal (None when not known).
    """

    def __init__(
        self,
        report: SegmentReporter,
        scan: SealScan,
        key: PublicKey | None,
        leaves: list[bytes],
        entry: CompactRange | None,
    ) -> None:
        self.report = report
        self.scan = scan
        self.key = key
        self.leaves = leaves
        self.entry = entry
        self.exit: CompactRange | None = None
        self.rejected: set[int] = set()
        """Cycles of checkpoints whose tree or note is wrong: they vouch for nothing."""

    def run(self, read: list[ReadCheckpoint], vouched: CheckpointCheck) -> None:
        """Check every 1.2 checkpoint; checkpoints with a problem stop vouching (``vouched``'s
        count and anchor are set again without them)."""
        trees = [c for _, _, c in read if c is not None and has_tree(c)]
        # A checkpoint already found unsigned, badly signed or not matching is not
        # reported twice: only those that vouch have their note checked.
        vouching = {id(c) for c in vouched.vouching}
        for c in trees:
            if id(c) in vouching:
                self._note(c, vouched.key_of.get(id(c), self.key))
        self._tree(trees)
        if self.rejected:
            kept = [c for c in vouched.vouching if c.cycle not in self.rejected]
            vouched.valid -= len(vouched.vouching) - len(kept)
            vouched.vouching = kept
            newest = max(kept, key=lambda c: c.cycle, default=None)
            vouched.anchor = None if newest is None else Anchor(newest.cycle, newest.t_ns)

    def _follows_chain(self) -> bool:
        scan = self.scan
        num = scan.num
        return (
            len(self.leaves) == len(num)
            and all(scan.link_ok)
            and not scan.damaged
            and not scan.bad_positions
            and all(num[i] < num[i + 1] for i in range(len(num) - 1))
        )

    def _tree(self, trees: list[Checkpoint]) -> None:
        if not self._follows_chain():
            return  # exit stays unknown: taken up again at the next segment's checkpoint
        position = {cycle: i for i, cycle in enumerate(self.scan.num)}
        at = sorted(
            ((position[c.cycle], c) for c in trees if c.cycle in position), key=lambda pc: pc[0]
        )
        tree = None if self.entry is None else CompactRange.restore(*self.entry.state())
        leaves, next_leaf = self.leaves, 0
        for p, c in at:
            if tree is None:
                tree = checkpoint_range(c)
                if tree is None:
                    self._mismatch(c, "its range does not make its root at its tree size")
                next_leaf = p + 1
                continue
            while next_leaf <= p:
                tree.append(leaves[next_leaf])
                next_leaf += 1
            self._compare(c, tree)
        if tree is not None:
            for leaf in leaves[next_leaf:]:
                tree.append(leaf)
        self.exit = tree

    def _compare(self, c: Checkpoint, tree: CompactRange) -> None:
        root = tree.root().hex()
        if c.tree_size != tree.size or c.root != root:
            self._mismatch(
                c,
                f"it states tree size {c.tree_size} with root {(c.root or '?')[:16]}…, the "
                f"robot's seals give size {tree.size} with root {root[:16]}…",
            )
        elif c.range != [h.hex() for h in tree.hashes]:
            self._mismatch(c, "its compact range differs from the tree of the robot's seals")

    def _mismatch(self, c: Checkpoint, message: str) -> None:
        self.rejected.add(c.cycle)
        self.report.finding(
            "tree_mismatch",
            f"checkpoint at cycle {c.cycle}: {message}",
            CycleRange(c.cycle, c.cycle, c.t_ns, c.t_ns),
        )

    def _note(self, c: Checkpoint, key: PublicKey | None) -> None:
        """The note against the checkpoint (whose head and signature are in order), with
        the key that signed the checkpoint (after any rotation)."""
        state = check_note(c, key)
        problem = _NOTE_PROBLEMS.get(state)
        if problem is None:
            return
        kind, message = problem
        self.rejected.add(c.cycle)
        self.report.finding(
            kind,
            f"checkpoint at cycle {c.cycle}: {message}",
            CycleRange(c.cycle, c.cycle, c.t_ns, c.t_ns),
        )
