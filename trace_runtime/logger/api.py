"""``AuditLogger``: the per-cycle audit trail API a robot's control loop calls.

The control thread does little: ``cycle()`` hands out a ``CycleBuilder``
(``trace_runtime.logger.cycle_builder``), which keeps built records as they are and validates and
encodes plain dicts at once, and ``commit()`` hands the cycle to a bounded queue
(``trace_runtime.logger.handover``). A writer thread (``trace_runtime.logger.writer_thread``)
encodes the built records canonically, seals each cycle into the hash chain and writes a chunk
per batch (``trace_runtime.logger.chain_writer``), so every committed cycle reaches the OS
within one period.
How it writes is ``LoggerConfig``; what it did is ``LoggerStats``
(``trace_runtime.logger.config``).

Failure policy (see schemas/PROFILE.md, "Dropped cycles"): nothing about I/O ever raises
into the control loop. A full queue, a failed write, a lost disk or permission: the cycle
is dropped and counted, the first failure of each kind is logged once through ``logging``,
and the next seal that is written carries the count in ``dropped``. A segment deleted under
the writer is noticed at the next batch and replaced; ``close()`` is bounded in time even
when the disk hangs. One live logger per robot and log root, enforced by an OS file lock
(``trace_runtime.logger.lock``; a second one raises ``LogLockedError``).
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from time import perf_counter_ns
from typing import Any

from trace_runtime.errors import LogLockedError, RecordError, UsageError
from trace_runtime.live_writers import lock_path
from trace_runtime.logger.chain_writer import ChainWriter
from trace_runtime.logger.config import LoggerConfig, LoggerStats
from trace_runtime.logger.cycle_builder import UNTIMED, CycleBuilder, TimedCycleBuilder
from trace_runtime.logger.handover import PendingCycle
from trace_runtime.logger.lock import WriterLock
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.logger.writer_thread import WriterThread
from trace_runtime.records import GENESIS
from trace_runtime.session import MIN_PERIOD_NS, SessionInfo
from trace_runtime.tlog.keys import PublicKey, Signer
from trace_runtime.tlog.signers import open_signer
from trace_runtime.tlog.token import TokenSigner

__all__ = ["AuditLogger", "CycleBuilder", "LogLockedError", "LoggerConfig", "LoggerStats"]


class AuditLogger:
    """Writes a robot's decision cycles as a hash-chained TRACE MCAP log.

    ``path`` is one ``.mcap`` file, or a directory used as a log root: segments then go to
    ``ROOT/hot/<robot_id>_<segment>.mcap`` and the chain and cycle numbers continue from the
    newest segment already there, across restarts.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        robot_id: str,
        period_s: float = 0.1,
        software_version: str = "",
        policy_version: str = "",
        clock: str = "system",
        config: LoggerConfig | None = None,
    ) -> None:
        self.config = config or LoggerConfig()
        _check_arguments(robot_id, period_s, self.config)
        # A bad key file is a set-up error the integrator must see: it raises here.
        key = self.config.checkpoint_key
        self._opened: list[TokenSigner] = []  # token sessions this logger opened: it closes them
        signer: Signer | None = self._open_key(key) if isinstance(key, str | Path) else key
        if self.config.next_key is not None and signer is None:
            raise UsageError("next_key needs checkpoint_key: the key it follows announces it")
        self.path = Path(path)
        self.is_root = self.path.suffix != ".mcap"
        self.stats = LoggerStats()
        self._closed = False
        self._open_cycle: CycleBuilder | None = None
        self._sensor_seq: dict[str, int] = {}
        # Drops are declared by the seal of the next cycle written after them. The control
        # thread counts what it drops before the hand-over; the writer counts failed writes.
        self._undeclared_control = 0  # control thread only

        # One live writer per robot and log root: taken before reading the resume point, so
        # two processes cannot both continue the same chain. Raises LogLockedError.
        writer_lock = WriterLock.take(lock_path(self.path, self.is_root, robot_id))
        try:
            session = self._first_session(
                robot_id, period_s, software_version, policy_version, clock
            )
            rotate_to: Signer | None = None
            if self.config.next_key is not None:
                signer, rotate_to = self._start_keys(signer, robot_id)
            self._chain = ChainWriter(
                self.path,
                session,
                is_root=self.is_root,
                config=self.config,
                stats=self.stats,
                signer=signer,
                writer_lock=writer_lock,
            )
            if rotate_to is not None:
                self._chain.rotate_key(rotate_to)
            self._next_cycle = session.first_cycle
            self._writer = WriterThread(self._chain, self.config, self._undeclared)
        except BaseException:
            if writer_lock is not None:
                writer_lock.release()
            for opened in self._opened:  # a logger that never started keeps no token session
                opened.close()
            raise
        self._queue = self._writer.queue  # None with threaded=False

    def _first_session(
        self,
        robot_id: str,
        period_s: float,
        software_version: str,
        policy_version: str,
        clock: str,
    ) -> SessionInfo:
        """The session record of the first segment this logger writes: in a log root, the
        chain and cycle numbers go on from the robot's newest segment there."""
        first_cycle, prev_seal, segment_no = 0, GENESIS, 0
        if self.is_root:
            # Deferred: the log-set reader is needed only for a root, not for a single file.
            from trace_runtime.logger.resume import resume_point

            first_cycle, prev_seal, segment_no = resume_point(self.path, robot_id)
        recordings: tuple[tuple[str, str], ...] = ()
        if self.config.recordings:
            # Deferred like the resume point: a robot that cites no recording loads no reader.
            from trace_runtime.reading.recordings import declare_recordings

            base = self.path if self.is_root else self.path.parent
            recordings = declare_recordings(self.config.recordings, base)
        return SessionInfo(
            robot_id=robot_id,
            period_ns=round(period_s * 1e9),
            software_version=software_version,
            policy_version=policy_version,
            clock=clock,
            segment=segment_no,
            prev_seal=prev_seal,
            first_cycle=first_cycle,
            recordings=recordings,
        )

    def _start_keys(self, signer: Signer | None, robot_id: str) -> tuple[Signer, Signer | None]:
        """``LoggerConfig.next_key``: (the key to sign with, the key to rotate to at once);
        the next key alone when the chain's newest signed checkpoint already hands on to it
        (a restart after the rotation)."""
        key = self.config.next_key
        assert key is not None and signer is not None  # checked before the lock was taken
        nxt = self._open_key(key) if isinstance(key, str | Path) else key
        if nxt.key_id == signer.key_id:
            raise UsageError("next_key is the checkpoint_key itself: nothing to rotate to")
        public = getattr(nxt, "public_key", None)
        if not isinstance(public, PublicKey):
            raise UsageError("next_key needs its public_key (it is announced)")
        if self.is_root:
            # Deferred like the resume point: only a logger told to rotate reads the keys.
            from trace_runtime.logger.resume import rotated_to

            if rotated_to(self.path, robot_id, signer, public):
                return nxt, None
        return signer, nxt

    def _undeclared(self) -> int:
        return self._undeclared_control

    @property
    def _session(self) -> SessionInfo:
        """The session record of the segment being written (for tests that look inside)."""
        return self._chain.session

    @property
    def _segment(self) -> SegmentWriter | None:
        """The segment being written (for tests that look inside)."""
        return self._chain.segment

    # --- control-thread API -------------------------------------------------------------

    def cycle(self, t_ns: int | None = None) -> CycleBuilder:
        """Begin the next decision cycle at ``t_ns`` (default: now, wall clock).

        A ``t_ns`` earlier than the previous cycle's is a clock step (chrony, a simulator
        reset), not an error: the writer begins a segment that declares it (PROFILE §4),
        the cycle number and the hash chain go on, and ``stats.clock_steps`` counts it.
        """
        if self._closed:
            raise UsageError("the logger is closed")
        if self._open_cycle is not None and not self._open_cycle._committed:
            raise UsageError(f"cycle {self._open_cycle.cycle} was begun but not committed")
        if t_ns is None:
            t_ns = time.time_ns()
        elif t_ns < 0:  # a bug in the robot, not a clock step: no clock counts below zero
            raise RecordError(f"cycle time {t_ns} ns is negative (PROFILE section 4)")
        number = self._next_cycle
        builder = (CycleBuilder if number & UNTIMED else TimedCycleBuilder)(self, number, t_ns)
        self._next_cycle += 1
        self._open_cycle = builder
        return builder

    begin = cycle

    def log_cycle(
        self,
        t_ns: int | None = None,
        *,
        perception: Any = None,
        belief: Any = None,
        action: Any = None,
        execution: Any = None,
    ) -> int:
        """Log a whole cycle of pre-built records in one call; return its cycle number."""
        with self.cycle(t_ns) as c:
            for add, record in (
                (c.perception, perception),
                (c.belief, belief),
                (c.action, action),
                (c.execution, execution),
            ):
                if record is not None:
                    add(record)
        return c.cycle

    def rotate_key(self, key: str | Path | Signer) -> None:
        """Rotate the checkpoint key to ``key`` (a key file, a ``pkcs11:`` URI or a
        ``Signer`` with a ``public_key``): the next checkpoint, signed by the current key,
        announces the new one, and later checkpoints are signed by it (profile 1.5), so
        ``verify --key OLD`` follows it. A key that cannot be loaded raises here."""
        if self._closed:
            raise UsageError("the logger is closed")
        signer = self._open_key(key) if isinstance(key, str | Path) else key
        self._chain.rotate_key(signer)

    def _open_key(self, key: str | Path) -> Signer:
        signer = open_signer(key)
        if isinstance(signer, TokenSigner):
            self._opened.append(signer)
        return signer

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until every committed cycle has been written; True if it got there."""
        return self._writer.flush(timeout_s)

    def close(self, timeout_s: float | None = 5.0) -> None:
        """Write what is queued, then the segment's summary and indexes. Idempotent.

        Waits at most ``timeout_s`` for the writer (a hung disk must not stall the robot's
        shutdown; None waits as long as it takes, for log generators with a deep queue).
        What it could not write by then is counted in
        ``stats.dropped_undelivered`` and logged once; should the disk come back, the writer
        thread (a daemon) ends the segment and declares them in ``trace.close``, and it keeps
        the robot's writer lock until then.
        """
        if self._closed:
            return
        self._closed = True
        if self._writer.close(timeout_s):
            # A writer still going (a hung disk) may yet sign its closing checkpoint.
            for signer in self._opened:
                signer.close()

    def __enter__(self) -> AuditLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- hand-over ----------------------------------------------------------------------

    def _next_sensor_sequence(self, topic: str) -> int:
        seq = self._sensor_seq.get(topic, 0)
        self._sensor_seq[topic] = seq + 1
        return seq

    def _commit(self, builder: CycleBuilder, started_ns: int | None) -> None:
        self.stats.committed += 1
        pending = PendingCycle(
            builder.cycle,
            builder.t_ns,
            builder._layers,
            builder._sensors,
            self._undeclared_control,
            -1 if started_ns is None else builder._cost_ns,
        )
        if started_ns is not None:  # a timed cycle: up to the hand-over
            pending.cost_ns += perf_counter_ns() - started_ns
        if self._queue is None:
            self._undeclared_control = 0
            self._writer.write_now(pending)
            return
        if self._queue.put(pending, block=self.config.when_full == "block"):
            self._undeclared_control = 0
        else:
            self.stats.dropped_queue_full += 1
            self._undeclared_control += 1
            self._chain.report_once("queue", "audit queue full: dropping cycles (writer too slow)")

    def _abort(self, builder: CycleBuilder) -> None:
        self.stats.dropped_aborted += 1
        self._undeclared_control += 1


def _check_arguments(robot_id: str, period_s: float, config: LoggerConfig) -> None:
    """Refuse, before anything is opened, what the profile does not allow (UsageError)."""
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", robot_id):
        raise UsageError(f"robot_id must be a simple name (letters, digits, _.-): {robot_id!r}")
    if not period_s * 1e9 >= MIN_PERIOD_NS:  # also refuses NaN
        raise UsageError(
            f"period_s must be at least {MIN_PERIOD_NS / 1e9:g} s (PROFILE section 2), "
            f"got {period_s}"
        )
    interval = config.checkpoint_interval_s
    if interval is not None and interval <= 0:
        raise UsageError(f"checkpoint_interval_s must be positive or None, got {interval}")
