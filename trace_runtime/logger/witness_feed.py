"""A robot's checkpoints submitted to a C2SP tlog-witness from the writer thread, never the
control loop: the compact range at the size the witness last cosigned and the leaf hashes
since (at most ``WITNESS_MAX_LEAVES``), a consistency proof built from them, the cosigned
note stored beside the log (``tlog.cosignature_store``), and every failure counted and
retried with the next checkpoint.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from trace_runtime.errors import WitnessProtocolError
from trace_runtime.logger.config import LoggerConfig, LoggerStats
from trace_runtime.tlog.cosignature_store import append_cosigned
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.witness_client import Submitted, submit

__all__ = ["WITNESS_MAX_LEAVES", "WitnessFeed", "witness_feed_for"]

log = logging.getLogger("trace_runtime")

WITNESS_MAX_LEAVES = 1 << 20
"""At most this many leaf hashes (32 MB, 29 h at 10 Hz) are kept since the size the witness
last cosigned; past it the logger proves from its current size, and a witness further
behind is caught up by ``trace-audit witness push``."""


class WitnessFeed:
    """A robot's checkpoints submitted to a C2SP tlog-witness, from the writer thread.

    It keeps the tree's compact range at ``witness_size`` (the size the witness last
    cosigned, as far as the logger knows) and the leaf hashes since, which is all a
    consistency proof from there needs (``chain_tree.consistency_proof_from``). Only the
    newest checkpoint of a batch is submitted. 200: the cosigned note is appended to the
    store beside the log (``witnessed.append_cosigned``) and the range moves up to that
    size; 409: the witness's size is learnt and the next checkpoint is proved from it (when
    the logger holds it: 0, or a size since its range); anything else is counted and retried
    with the next checkpoint. At start the witness is taken to be at the resumed size.
    """

    def __init__(
        self,
        url: str,
        *,
        timeout_s: float,
        store_root: Path,
        robot_id: str,
        tree: CompactRange,
        stats: LoggerStats,
        report_once: Callable[[str, str], None],
    ) -> None:
        self.url = url
        self.timeout_s = timeout_s
        self.store_root = store_root
        self.robot_id = robot_id
        self.stats = stats
        self._report_once = report_once
        self.base = CompactRange.restore(*tree.state())
        self._since = bytearray()  # leaf hashes after base.size, 32 bytes each
        self.witness_size: int = tree.size
        self._pending: tuple[str, int] | None = None

    def add_leaves(self, leaves: list[bytes]) -> None:
        """Leaves now on disk, in order."""
        if len(self._since) // 32 + len(leaves) > WITNESS_MAX_LEAVES:
            self._advance(self.base.size + len(self._since) // 32)
            self.witness_size = self.base.size
        self._since += b"".join(leaves)

    def offer(self, note: str, size: int) -> None:
        """The newest checkpoint written (its note and tree size): the next to submit."""
        self._pending = (note, size)

    def submit(self) -> None:
        """Submit the pending checkpoint, if any; never raises."""
        pending, self._pending = self._pending, None
        if pending is None:
            return
        note, size = pending
        try:
            proof = self._proof(size)
            if proof is None:
                self._failed(
                    f"the witness holds size {self.witness_size}, which this logger cannot "
                    "prove from (trace-audit witness push catches it up)"
                )
                return
            result = submit(self.url, self.witness_size, proof, note, timeout_s=self.timeout_s)
            self._answer(result, note, size)
        except (WitnessProtocolError, OSError, ValueError) as err:
            self._failed(f"could not submit a checkpoint to the witness: {err}")
        except Exception as err:  # the store and the client are plug points: never the robot
            self._failed(f"could not submit a checkpoint to the witness: {err}")

    def _proof(self, size: int) -> list[bytes] | None:
        old = self.witness_size
        if old in (0, size):
            return []
        held = len(self._since) // 32
        if old != self.base.size or not old < size <= old + held:
            return None
        from trace_runtime.reading.chain_tree import consistency_proof_from  # the reading floor

        since = self._since
        leaves = [bytes(since[i : i + 32]) for i in range(0, (size - old) * 32, 32)]
        return consistency_proof_from(self.base, leaves)

    def _answer(self, result: Submitted, note: str, size: int) -> None:
        if result.ok:
            append_cosigned(
                self.store_root, self.robot_id, note, result.cosignatures, witness_url=self.url
            )
            self.stats.witness_cosigned += 1
            self._advance(size)
            self.witness_size = size
            return
        if result.outcome == "conflict" and result.witness_size is not None:
            learnt = result.witness_size
            if self.base.size <= learnt <= self.base.size + len(self._since) // 32:
                self._advance(learnt)
            self.witness_size = learnt
            self._failed(f"the witness holds size {learnt} (409); proving from there next")
            return
        self._failed(
            f"the witness did not cosign ({result.outcome}"
            f"{f' {result.status}' if result.status else ''}: {result.detail})"
        )

    def _advance(self, size: int) -> None:
        """Move the kept range up to ``size`` (within the leaves held)."""
        count = size - self.base.size
        if count <= 0:
            return
        since = self._since
        for i in range(0, count * 32, 32):
            self.base.append(bytes(since[i : i + 32]))
        del since[: count * 32]

    def _failed(self, message: str) -> None:
        self.stats.witness_failures += 1
        self._report_once("witness", message)


def witness_feed_for(
    config: LoggerConfig,
    tree: CompactRange | None,
    *,
    store_root: Path,
    robot_id: str,
    stats: LoggerStats,
    report_once: Callable[[str, str], None],
) -> WitnessFeed | None:
    """The feed of a writer whose ``config`` names a witness, given the robot's tree (None:
    unknown, or its checkpoints carry no signed note); None, said once, when it cannot be."""
    if not config.witness:
        return None
    if tree is None:
        report_once("witness", "no checkpoint is submitted to the witness: it needs signed notes")
        return None
    return WitnessFeed(
        config.witness,
        timeout_s=config.witness_timeout_s,
        store_root=store_root,
        robot_id=robot_id,
        tree=tree,
        stats=stats,
        report_once=report_once,
    )
