"""``trace-audit witness push``: a log root's signed checkpoints submitted to a witness
afterwards (a robot that was offline), oldest first, from the size the witness holds.

Each robot's seals are read once (``chain_tree.robot_seal_leaves``); each 1.2 checkpoint
with a note, in tree order, is sent with the consistency proof from the witness's size. A
409 tells the witness's size: the same checkpoint is sent again with a proof from there
(or skipped when the witness already holds a larger tree). Each cosignature returned is
stored in the root's ``witness/<robot>.jsonl`` (``trace_runtime.tlog.cosignature_store``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from trace_audit.witness.tree import LevelTree
from trace_runtime.errors import RecordError
from trace_runtime.reading.chain_tree import robot_leaves
from trace_runtime.reading.logset import Log, open_log
from trace_runtime.records import Checkpoint
from trace_runtime.tlog.checkpoints import decode_checkpoint, iter_checkpoints
from trace_runtime.tlog.cosignature_store import append_cosigned
from trace_runtime.tlog.witness_client import submit

__all__ = ["PushReport", "RobotPush", "push_root", "robot_checkpoints"]


@dataclass(slots=True)
class RobotPush:
    """What one robot's checkpoints became at the witness."""

    robot_id: str
    origin: str = ""
    checkpoints: int = 0
    """1.2 checkpoints with a note in the log (distinct tree sizes)."""
    cosigned: int = 0
    skipped: int = 0
    """Already below the witness's size."""
    witness_size: int | None = None
    """The size the witness holds for the origin after the push (when it said)."""
    problems: list[str] = field(default_factory=list)


@dataclass(slots=True)
class PushReport:
    root: str
    witness: str
    robots: list[RobotPush] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(not r.problems for r in self.robots)


def robot_checkpoints(log: Log, robot: str) -> list[Checkpoint]:
    """A robot's 1.2 checkpoints that carry a note, one per tree size, by size."""
    by_size: dict[int, Checkpoint] = {}
    for segment in log.segments_of(robot):
        for message in iter_checkpoints(segment):
            try:
                checkpoint = decode_checkpoint(message.data)
            except RecordError:
                continue
            if checkpoint.note and checkpoint.tree_size and checkpoint.origin:
                by_size.setdefault(checkpoint.tree_size, checkpoint)
    return [by_size[size] for size in sorted(by_size)]


def push_root(
    root: str | Path,
    witness: str,
    *,
    robots: Sequence[str] = (),
    timeout_s: float = 5.0,
) -> PushReport:
    """Submit every robot's (or ``robots``') checkpoints; never raises for the network."""
    log = open_log(root)
    report = PushReport(str(root), witness)
    for robot in robots or log.robots:
        report.robots.append(_push_robot(log, Path(root), robot, witness, timeout_s))
    return report


def _push_robot(log: Log, root: Path, robot: str, witness: str, timeout_s: float) -> RobotPush:
    result = RobotPush(robot)
    checkpoints = robot_checkpoints(log, robot)
    result.checkpoints = len(checkpoints)
    if not checkpoints:
        result.problems.append("no signed profile 1.2 checkpoint to submit")
        return result
    tree = LevelTree(robot_leaves(log, robot))
    result.origin = checkpoints[-1].origin or ""
    known = 0  # the size the witness is believed to hold: found out from its first 409
    for checkpoint in checkpoints:
        size = checkpoint.tree_size or 0
        note = checkpoint.note or ""
        if size > tree.size or tree.root(size).hex() != checkpoint.root:
            result.problems.append(f"checkpoint of size {size} does not match the seals: not sent")
            continue
        if size < known:
            result.skipped += 1
            continue
        for _attempt in range(2):
            answer = submit(
                witness, known, tree.consistency_proof(known, size), note, timeout_s=timeout_s
            )
            if answer.outcome == "conflict" and answer.witness_size is not None:
                if answer.witness_size == known:  # same size, another root: a fork
                    result.problems.append(f"the witness holds another tree of size {known} (409)")
                    break
                known = answer.witness_size
                result.witness_size = known
                if known > tree.size:
                    result.problems.append(
                        f"the witness holds size {known}, beyond this log's {tree.size} "
                        "seals: the log has lost its newest cycles"
                    )
                    return result
                if known > size:
                    result.skipped += 1
                    break
                continue
            if answer.ok:
                append_cosigned(root, robot, note, answer.cosignatures, witness_url=witness)
                result.cosigned += 1
                known = size
                result.witness_size = size
            elif answer.outcome == "unreachable":
                result.problems.append(f"witness unreachable: {answer.detail}")
                return result
            else:
                result.problems.append(
                    f"size {size}: {answer.outcome} ({answer.status}): {answer.detail}"
                )
            break
    return result
