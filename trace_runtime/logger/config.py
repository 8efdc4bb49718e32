"""What an integrator sets and reads on an ``AuditLogger``: ``LoggerConfig`` (how it writes)
and ``LoggerStats`` (the counters a robot exports to its health monitoring)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Literal

from trace_runtime.errors import UsageError
from trace_runtime.tlog.keys import Signer

__all__ = ["LoggerConfig", "LoggerStats", "Opener", "default_opener", "default_origin"]

Opener = Callable[[Path], BinaryIO]


def default_origin(robot_id: str) -> str:
    """The checkpoint origin of a robot whose ``LoggerConfig.origin`` is None."""
    return f"trace.local/{robot_id}"


def default_opener(path: Path) -> BinaryIO:
    """Open a new segment file for writing (``LoggerConfig.opener`` when none is given).

    Never over a file that exists: a log is evidence, and a robot started twice on the same
    file name would erase the first run's. The first segment is opened when the logger is
    made, so this is a set-up error the integrator sees there (``UsageError``); a later
    segment that finds its name taken is a failed write, dropped and counted like any."""
    try:
        return open(path, "xb")
    except FileExistsError as err:
        raise UsageError(
            f"{path} exists: the logger does not overwrite a log (log into a folder, a log "
            "root, to continue the robot's chain there; or give a new file name)"
        ) from err


@dataclass(frozen=True, slots=True)
class LoggerConfig:
    """How the logger writes. Defaults suit a 10 Hz robot on a local disk."""

    threaded: bool = True
    """Write on a background thread (robots). False writes at ``commit()`` (simulators, tests)."""
    batch_cycles: int = 1
    """With ``threaded=False``: cycles per chunk. Above 1, a crash can lose that many cycles,
    and a failed write drops them all; for simulators and log generators, not robots."""
    queue_cycles: int = 256
    """Bound of the hand-over queue, in cycles."""
    when_full: Literal["drop", "block"] = "drop"
    """Queue full: drop the cycle and count it (default; never stalls the loop) or block."""
    max_batch_cycles: int = 512
    """At most this many cycles per chunk when the writer is catching up."""
    fsync_interval_s: float | None = 1.0
    """fsync the segment at most this often (None: leave it to the OS)."""
    max_segment_s: float = 3600.0
    """Rotate to a new segment after this much log time (log roots only)."""
    max_segment_bytes: int = 512 * 1024 * 1024
    """Rotate to a new segment past this size (log roots only)."""
    compression_level: int = 3
    opener: Opener | None = None
    """How segment files are opened; a plug point for custom storage and fault injection."""
    checkpoint_interval_s: float | None = 10.0
    """Write a /trace/checkpoint (the chain head) after the first seal at or past each
    multiple of this much log time from the segment's first cycle, however cycles are
    batched into chunks; one is always written when a segment closes. None: only then."""
    checkpoint_key: str | Path | Signer | None = None
    """Sign checkpoints: an Ed25519 private key file (``trace-audit keygen``), an RFC 7512
    ``pkcs11:`` URI of a key held in a token (``tlog.token``; the ``token`` extra), or a
    ``Signer``.
    None writes unsigned checkpoints (chain-head anchors only). A ``Signer`` that also has a
    ``public_key`` (a ``keys.PublicKey``, as ``Ed25519Signer`` has) signs each checkpoint's
    C2SP note too (profile 1.2); one without gives checkpoints whose tree is unsigned."""
    next_key: str | Path | Signer | None = None
    """Rotate the checkpoint key to this one (a key file, a ``pkcs11:`` URI, or a ``Signer``
    with a ``public_key``) unless the robot's chain already has: at start the logger reads
    its newest checkpoint that either key signed (``resume.rotated_to``, profile 1.5).
    ``next_key``'s, or announcing it: it signs with ``next_key`` from the first checkpoint.
    Otherwise it signs with ``checkpoint_key`` and its first checkpoint announces
    ``next_key`` (``AuditLogger.rotate_key``). So the same configuration may be started
    again and again (a service's restarts, a recorder's reconnecting robots) and rotates
    once. Needs ``checkpoint_key``."""
    origin: str | None = None
    """The C2SP checkpoint origin naming this robot's log, and the key name its notes are
    signed under (e.g. ``fleet.example.com/amr-7``; no spaces, no ``+``). None:
    ``trace.local/<robot_id>``."""
    witness: str | None = None
    """A C2SP tlog-witness (``http(s)://host:port``, e.g. ``trace-audit witness serve``):
    after writing a checkpoint the writer thread submits its note there with a consistency
    proof from the size the witness last cosigned, and stores the cosigned note beside the
    log (``<root>/witness/<robot_id>.jsonl``). Failures are counted
    (``LoggerStats.witness_failures``) and retried with the next checkpoint. Needs a
    ``checkpoint_key`` (only signed notes are submitted)."""
    witness_timeout_s: float = 2.0
    """How long one submission may take; the writer thread waits at most this long."""
    recordings: tuple[str | Path, ...] = ()
    """The sensor recordings the robot's evidence refs cite: a rosbag2 folder (as ``ros2 bag
    record -o NAME`` makes it, split files and all) or one MCAP file, by path; it need not
    exist yet. Each is declared in every segment (``trace.session`` ``recordings``), so every
    command finds it without being told, and followed on the writer thread, so that every
    message recorded in it is sealed into the robot's chain, cited or not (profile 1.4)."""
    recording_window_s: float = 1.0
    """The recording time one seal of a recording's messages covers."""
    recording_settle_s: float = 1.0
    """How long a window stays open after its end, in recording time (or, when the recording
    stops growing, in wall time) for messages its recorder writes late: a message is sealed
    at most ``recording_window_s + recording_settle_s`` plus one poll after it is on disk."""


@dataclass(slots=True)
class LoggerStats:
    """Counters a robot can export to its health monitoring."""

    committed: int = 0
    written: int = 0
    """Cycles on disk (cycles of a segment later lost with its storage are taken back out)."""
    dropped_queue_full: int = 0
    dropped_io: int = 0
    dropped_aborted: int = 0
    dropped_storage_lost: int = 0
    """Cycles written into a segment that was then deleted under the writer."""
    dropped_undelivered: int = 0
    """Cycles still queued or being written when ``close()`` gave up waiting (a hung disk)."""
    segments: list[Path] = field(default_factory=list)
    bytes_written: int = 0
    checkpoints: int = 0
    checkpoint_failures: int = 0
    witness_cosigned: int = 0
    """Checkpoints the witness cosigned (stored beside the log)."""
    witness_failures: int = 0
    """Submissions that did not end in a stored cosignature: the witness unreachable or
    refusing, a 409 (it holds another size; the next checkpoint is proved from there), a
    size the logger cannot prove from, or a store that could not be written."""
    clock_steps: int = 0
    """Times a cycle was begun earlier than the one before it: each began a segment that
    declares the step (PROFILE section 4)."""
    tree_failures: int = 0
    """Checkpoints written without their Merkle tree: the tree could not be resumed at start
    (the chain on disk could not be followed to its last seal) or computed."""

    @property
    def dropped(self) -> int:
        return (
            self.dropped_queue_full
            + self.dropped_io
            + self.dropped_aborted
            + self.dropped_storage_lost
            + self.dropped_undelivered
        )
