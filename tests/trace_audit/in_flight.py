"""A crashed segment cut while a cycle was being written: its layer messages, no seal."""

from __future__ import annotations

from pathlib import Path

from tests.trace_audit.conftest import rewrite_segment
from trace_runtime import open_segment
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.records import TOPIC_SEAL


def cut_in_flight(
    src: Path, dst: Path, *, unsealed: int | None = None, finished: bool = False
) -> Path:
    """Copy segment ``src`` to ``dst`` as a robot killed mid-write leaves it: no summary, no
    footer, and cycle ``unsealed`` (default: the last one) without its seal.

    Small chunks are flushed as a logger flushes its batches, so what precedes the cut reads
    back whole. Leaving out a seal other than the last one makes an unsealed cycle in the
    middle of a crashed segment: that one is a finding, not the cycle in flight.
    ``finished=True`` closes the file instead: a closed segment whose last cycle has no seal
    was not cut by a crash, so that unsealed cycle is a finding too."""
    seals = [m.sequence for m in open_segment(src).iter_messages() if m.topic == TOPIC_SEAL]
    drop = seals[-1] if unsealed is None else unsealed

    def without_its_seal(msg: RawMessage) -> bytes | None:
        return None if msg.topic == TOPIC_SEAL and msg.sequence == drop else msg.data

    return rewrite_segment(src, dst, without_its_seal, chunk_size=2048, finish=finished)
