"""A robot's checkpoint key followed through the rotations its chain announces (profile 1.5),
for the readers that check one statement of the chain rather than all of it: ``publish``
(the newest note it serves) and ``prove`` (the announcements a bundle carries).

The rotation logic is ``trace_runtime.tlog.rotation``'s, the one ``verify`` uses: from the
key given, an announcing checkpoint signed by the chain's key at that point, whose
announcement verifies under that key, makes the announced key the chain's. Only the
announcing checkpoints are read here (a handful in a log's life); verify reads them all and
reports each one out of place, which is not these readers' question.
"""

from __future__ import annotations

from trace_runtime.errors import RecordError
from trace_runtime.reading.logset import Log
from trace_runtime.records import Checkpoint
from trace_runtime.tlog.checkpoints import check_checkpoint, decode_checkpoint, iter_checkpoints
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.rotation import KeyChain, follow_keys

__all__ = ["announcing_checkpoints", "followed_keys", "signed_by"]


def announcing_checkpoints(log: Log, robot: str, *, before: str | None = None) -> list[Checkpoint]:
    """The robot's checkpoints that announce a key, in chain order (every one, also two of
    one tree size: a closing checkpoint may announce after a periodic one of its size);
    ``before``, a note: only those before the checkpoint that carries it (a cosigned note
    begins with the robot's), whose key they lead to."""
    found: list[Checkpoint] = []
    for segment in log.segments_of(robot):
        for message in iter_checkpoints(segment):
            if before is None and b'"next_key' not in message.data:  # most: not decoded
                continue
            try:
                checkpoint = decode_checkpoint(message.data)
            except RecordError:  # verify reports it; it announces nothing here
                continue
            if before is not None and checkpoint.note and before.startswith(checkpoint.note):
                return found
            if checkpoint.next_key is not None or checkpoint.next_key_signature is not None:
                found.append(checkpoint)
    return found


def signed_by(checkpoint: Checkpoint, key: PublicKey) -> bool:
    """Whether ``key`` signed the checkpoint (its own signature, as verify checks it)."""
    return check_checkpoint(checkpoint, key) == "valid"


def followed_keys(announcing: list[Checkpoint], key: PublicKey) -> KeyChain:
    """The keys from ``key`` through ``announcing`` (``announcing_checkpoints``)."""
    return follow_keys(announcing, key, signed_by)
