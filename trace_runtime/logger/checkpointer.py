"""A robot's checkpoints as the writer thread makes them: when a periodic one is due (a
grid in log time), and the checkpoint message itself, signed with the robot's key and, as a
C2SP note, by the same key named after the robot's origin. Never raises: a checkpoint that
cannot be built is counted and the trail goes on; one that cannot be signed is written
unsigned (it still anchors the chain head; ``verify`` reports it unsigned).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

from trace_runtime.errors import UsageError
from trace_runtime.logger.config import LoggerConfig, LoggerStats
from trace_runtime.logger.mcap_out import OutMessage
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.records import TOPIC_CHECKPOINT, Checkpoint
from trace_runtime.session import SessionInfo
from trace_runtime.tlog.checkpoints import encode_checkpoint, make_checkpoint
from trace_runtime.tlog.keys import PublicKey, Signer
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.rotation import announce
from trace_runtime.tlog.signed_note import NoteSigner

__all__ = ["Checkpointer"]


class Checkpointer:
    """The checkpoints of one robot's chain; the newest one's signed note is kept for the
    witness feed until taken (``take_note``)."""

    def __init__(
        self,
        config: LoggerConfig,
        stats: LoggerStats,
        *,
        origin: str,
        signer: Signer | None,
        report_once: Callable[[str, str], None],
    ) -> None:
        self._interval_s = config.checkpoint_interval_s
        self._stats = stats
        self._report_once = report_once
        self.origin = origin
        self._signer = signer
        self.note_signer = self._note_signer(signer)
        # A key to rotate to: set by the control thread, taken by the writer thread.
        self._next: tuple[Signer, PublicKey] | None = None
        self._next_lock = threading.Lock()
        self._note: tuple[str, int] | None = None  # the newest note and its tree size
        self._due_ns: int | None = None  # log time the next periodic one is due

    def _note_signer(self, signer: Signer | None) -> NoteSigner | None:
        """The checkpoint key as a C2SP note signer named ``origin``: it needs the public
        key, which ``Ed25519Signer`` has and another ``Signer`` may (``public_key``)."""
        if signer is None:
            return None
        public = getattr(signer, "public_key", None)
        if not isinstance(public, PublicKey):
            self._report_once(
                "note",
                "the checkpoint signer has no public_key: checkpoint notes (the signed tree) "
                "are not written",
            )
            return None
        return NoteSigner(self.origin, signer, public.raw)

    def rotate(self, signer: Signer) -> None:
        """Rotate to ``signer``'s key: the next checkpoint announces it, signed by the
        current key (profile 1.5), and the ones after it are signed by it. Without a current
        key there is nothing to announce it with: it signs from the next checkpoint on."""
        public = getattr(signer, "public_key", None)
        if not isinstance(public, PublicKey):
            raise UsageError("a key to rotate to needs its public_key (it is announced)")
        with self._next_lock:
            self._next = (signer, public)

    def _pending(self) -> tuple[Signer, PublicKey] | None:
        """The rotation asked for, if any; with no current key it takes effect at once."""
        with self._next_lock:
            pending = self._next
            if pending is not None and self._signer is None:
                self._next = None
                self._signer = pending[0]
                self.note_signer = self._note_signer(pending[0])
                return None
        return pending

    def _announce(self, checkpoint: Checkpoint, pending: tuple[Signer, PublicKey]) -> Checkpoint:
        """A signed checkpoint with the pending rotation's announcement, after which the new
        key signs; one written unsigned (the signer failed) announces nothing: the rotation
        waits for the next checkpoint the old key signs."""
        signer = self._signer
        if signer is None or checkpoint.signature is None:
            return checkpoint
        fields = announce(checkpoint, signer, self.origin, pending[1])
        with self._next_lock:
            if self._next is pending:  # not replaced meanwhile by another rotate()
                self._next = None
        self._signer = pending[0]
        self.note_signer = self._note_signer(pending[0])
        return checkpoint.model_copy(update=fields)

    def take_note(self) -> tuple[str, int] | None:
        """The signed note and tree size of the newest checkpoint made since the last call
        (None when none was, or none was signed); the witness is offered only the newest."""
        note, self._note = self._note, None
        return note

    def new_segment(self) -> None:
        """A new segment starts its own grid."""
        self._due_ns = None

    def due(self, t_ns: int, segment_start_ns: int | None) -> bool:
        """Whether a periodic checkpoint goes after the seal of the cycle at ``t_ns``.

        They fall on a grid in log time: the first seal at or past each multiple of the
        interval from the segment's first cycle, so their spacing does not depend on how
        cycles were batched into chunks. After a pause longer than the interval there is one
        checkpoint, not one per missed multiple. A checkpoint that could not be built or
        signed still counts as done: a signer that is down (an HSM that times out) is asked
        again an interval later, not on every cycle.
        """
        if self._interval_s is None:
            return False
        step = max(1, round(self._interval_s * 1e9))
        due = self._due_ns
        if due is None:
            start = t_ns if segment_start_ns is None else segment_start_ns
            due = self._due_ns = start + step
        if t_ns < due:
            return False
        self._due_ns = due + ((t_ns - due) // step + 1) * step
        return True

    def message(
        self,
        segment: SegmentWriter,
        session: SessionInfo,
        tree: CompactRange | None,
        *,
        cycle: int,
        t_ns: int,
        head: str,
        sealed: int,
        final: bool,
    ) -> OutMessage | None:
        """Build (and sign) a checkpoint message; None if that fails: never raises."""
        build = functools.partial(
            make_checkpoint,
            tree=tree,
            origin=self.origin if tree is not None else None,
            robot_id=session.robot_id,
            segment=session.segment,
            first_cycle=session.first_cycle,
            cycle=cycle,
            t_ns=t_ns,
            sealed=sealed,
            head=head,
            final=final,
        )
        stats = self._stats
        try:
            if tree is None:
                stats.tree_failures += 1
            try:
                pending = self._pending()
                checkpoint = build(signer=self._signer, note_signer=self.note_signer)
                if pending is not None:
                    checkpoint = self._announce(checkpoint, pending)
            except Exception as err:  # a signer is a plug point (an HSM that is gone)
                if self._signer is None:
                    raise
                stats.checkpoint_failures += 1
                self._report_once("sign", f"could not sign a checkpoint, wrote it unsigned: {err}")
                checkpoint = build()
            data = encode_checkpoint(checkpoint)
            if checkpoint.note is not None and checkpoint.tree_size is not None:
                self._note = (checkpoint.note, checkpoint.tree_size)
            return OutMessage(segment.channel(TOPIC_CHECKPOINT), cycle, t_ns, data)
        except Exception as err:  # the audit trail goes on without this checkpoint
            stats.checkpoint_failures += 1
            self._report_once("checkpoint", f"could not build a checkpoint: {err}")
            return None
