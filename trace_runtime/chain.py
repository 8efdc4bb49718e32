"""The per-cycle hash chain: each seal names the digests of its cycle's layer messages and
the digest of the previous seal, so any change, removal or reordering breaks a link.

This is the chain's primitive, below the reader's ``Cycle``; the check of one cycle against
its seal, built on it, is ``trace_runtime.encoding.seal_check.verify_cycle``.
"""

from __future__ import annotations

import hashlib

from trace_runtime.records import GENESIS

__all__ = ["GENESIS", "NO_SENSORS", "digest", "sensor_cover", "sensor_line"]


def digest(data: bytes) -> str:
    """SHA-256 hex digest of a message's data (its canonical bytes)."""
    return hashlib.sha256(data).hexdigest()


def sensor_line(topic: str, sequence: int, log_time_ns: int, data_digest: str) -> bytes:
    """One sensor reading as the seal's ``sensors`` digest covers it (PROFILE §6): its topic
    (after its UTF-8 length, so a topic holding a newline cannot pass for two readings), its
    sequence, log time and data digest, each ended by a newline. Moving a reading to another
    topic or time breaks the seal as surely as changing its bytes."""
    name = topic.encode()
    return b"%d:%s\n%d\n%d\n%s\n" % (len(name), name, sequence, log_time_ns, data_digest.encode())


def sensor_cover(lines: list[bytes]) -> tuple[int, str]:
    """A seal's ``sensors``: how many readings the cycle logged, and the SHA-256 hex of their
    ``sensor_line``s concatenated in file order (``NO_SENSORS`` for none). The readings are
    the cycle's messages on ``/sensors/`` topics (``records.SENSOR_PREFIX``, PROFILE §3):
    other channels, which readers ignore (a Foxglove view beside the records), are not."""
    return len(lines), hashlib.sha256(b"".join(lines)).hexdigest()


NO_SENSORS = hashlib.sha256(b"").hexdigest()
"""The ``sensors`` digest of a cycle that logged no sensor reading."""
