"""``AuditLogger``: the per-cycle audit trail API a robot's control loop calls.

The control thread does little: it keeps a reference to a built record (an ``isinstance``),
validates and encodes a plain dict at once (see ``trace_runtime.codec.check_layer``),
encodes the small sensor payloads it needs digests for, and hands the cycle to a bounded
queue. A writer thread encodes the built records canonically, seals the cycle into the hash
chain and writes a chunk per batch, so every committed cycle reaches the OS within one
period.

Neither thread lets go of the GIL per message: the writer only for the batch's compression
and write. A thread that lets go of the GIL waits up to the switch interval (5 ms) to get it
back from a busy one; the v1 writer let go once per message (``hashlib`` does, for data of
2 KiB and more) and starved behind a control thread validating dicts (docs/performance.md).

Failure policy (see schemas/PROFILE.md, "Dropped cycles"): nothing about I/O ever raises
into the control loop. A full queue, a failed write, a lost disk or permission: the cycle
is dropped and counted, the first failure of each kind is logged once through ``logging``,
and the next seal that is written carries the count in ``dropped``. A segment deleted under
the writer is noticed at the next batch and replaced; ``close()`` is bounded in time even
when the disk hangs. One live logger per robot and log root, enforced by an OS file lock.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import re
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from time import perf_counter_ns
from types import TracebackType
from typing import Any, BinaryIO, Literal, Protocol

from pydantic import ValidationError

from trace_runtime.chain import digest
from trace_runtime.checkpoints import encode_checkpoint, make_checkpoint
from trace_runtime.codec import (
    EncodedLayer,
    LayerValue,
    check_layer,
    digest_keeping_gil,
    encode_json,
    encode_layer,
    encode_seal_fields,
)
from trace_runtime.costs import TIMING_METADATA, CostHistogram
from trace_runtime.errors import LogLockedError, RecordError, UsageError
from trace_runtime.keys import Signer, load_signer
from trace_runtime.records import (
    GENESIS,
    LAYER_MODELS,
    SENSOR_PREFIX,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_CHECKPOINT,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
    EvidenceRef,
    validate_record,
)
from trace_runtime.segment import MessageFields, OutMessage, SegmentWriteError, SegmentWriter
from trace_runtime.session import MIN_PERIOD_NS, TIERS, SessionInfo

_validate_evidence_ref = EvidenceRef.__pydantic_validator__.validate_python

if sys.platform != "win32":  # Linux is the target; elsewhere the writer lock is skipped
    import fcntl

log = logging.getLogger("trace_runtime")

CLOSE_METADATA = "trace.close"
"""Metadata a segment ends with when cycles were dropped after its last seal."""

Opener = Callable[[Path], BinaryIO]


def _default_opener(path: Path) -> BinaryIO:
    return open(path, "wb")


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
    """Sign checkpoints: an Ed25519 private key file (``trace-audit keygen``) or a ``Signer``.
    None writes unsigned checkpoints (chain-head anchors only)."""


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

    @property
    def dropped(self) -> int:
        return (
            self.dropped_queue_full
            + self.dropped_io
            + self.dropped_aborted
            + self.dropped_storage_lost
            + self.dropped_undelivered
        )


@dataclass(slots=True)
class _PendingCycle:
    cycle: int
    t_ns: int
    layers: dict[str, LayerValue]
    sensors: list[tuple[str, int, int, bytes]]
    dropped_before: int
    cost_ns: int


class _Wakeup:
    """Wakes one sleeping thread from another, cheaply for the thread that wakes it.

    ``threading.Event.set`` runs a Python-level condition variable (a few microseconds) on
    every call; here ``notify`` costs a flag check, plus one C-level lock release only when
    the other thread is actually asleep. A released lock is a pending wake-up: the sleeper
    then returns at once and checks again, so a wake-up is never lost, at worst early.
    """

    __slots__ = ("_lock", "_sleeping")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._lock.acquire()  # held: no wake-up pending
        self._sleeping = False

    def notify(self) -> None:
        """Wake the sleeper, if there is one (call after making ``ready`` true)."""
        if self._sleeping:
            self.wake()

    def wake(self) -> None:
        """Leave a wake-up pending, whether or not anyone sleeps now."""
        with contextlib.suppress(RuntimeError):  # already released: one is pending
            self._lock.release()

    def sleep(self, ready: Callable[[], bool]) -> None:
        """Sleep until woken, unless ``ready()`` holds once ``notify`` can see the sleeper:
        whatever was made ready before that is seen here, and anything after it wakes us."""
        self._sleeping = True
        try:
            if not ready():
                self._lock.acquire()
        finally:
            self._sleeping = False


class _Handover:
    """The bounded hand-over from the control thread to the writer thread.

    One producer, one consumer. ``collections.deque`` appends and pops are atomic, so the
    control thread pays for an append and, when the writer sleeps, a lock release: not for
    a lock-guarded ``queue.Queue`` nor an ``Event``. Each counter is written by one thread.
    """

    def __init__(self, bound: int) -> None:
        self._items: deque[_PendingCycle] = deque()
        self._bound = bound
        self._wake = _Wakeup()
        self._space = threading.Event()
        self._closed = False
        self._put = 0  # producer only
        self._done = 0  # consumer only
        self.discarded: list[_PendingCycle] = []  # what abandon() took out, never written

    def put(self, item: _PendingCycle, *, block: bool) -> bool:
        """Hand ``item`` over; False when full and not blocking."""
        while len(self._items) >= self._bound:
            if not block:
                return False
            self._space.clear()
            if len(self._items) >= self._bound:
                self._space.wait(0.01)
        self._put += 1
        self._items.append(item)
        self._wake.notify()
        return True

    def take(self, most: int) -> list[_PendingCycle]:
        """Up to ``most`` items, waiting for at least one; [] once closed and drained."""
        while True:
            batch: list[_PendingCycle] = []
            # abandon() may empty the deque under us: an empty popleft ends the batch.
            with contextlib.suppress(IndexError):
                while self._items and len(batch) < most:
                    batch.append(self._items.popleft())
            if batch:
                self._space.set()
                return batch
            if self._closed:
                return []
            self._wake.sleep(self._has_work)

    def _has_work(self) -> bool:
        return bool(self._items) or self._closed

    def done(self, count: int) -> None:
        self._done += count

    def wait_idle(self, timeout_s: float) -> bool:
        """Poll until everything handed over is written (flush is rare; polling is simple)."""
        deadline = time.monotonic() + timeout_s
        while self._done != self._put and time.monotonic() < deadline:
            time.sleep(0.0005)
        return self._done == self._put

    @property
    def undone(self) -> int:
        """Cycles handed over and not yet written (or failed)."""
        return self._put - self._done

    def close(self) -> None:
        self._closed = True
        self._wake.wake()

    def abandon(self) -> None:
        """Close and take every waiting item out, so the consumer writes nothing more."""
        self._closed = True
        with contextlib.suppress(IndexError):  # the consumer may take the last one first
            while self._items:
                self.discarded.append(self._items.popleft())
        self._wake.wake()


def next_cycle_time(t_ns: int | None, previous_ns: int) -> int:
    """The time of the cycle being begun: ``t_ns``, or now when None. ``RecordError`` when
    it is earlier than ``previous_ns``, the time of the cycle begun before it (0 before the
    first): time never goes backwards within a session (schemas/PROFILE.md §4)."""
    if t_ns is None:
        return time.time_ns()
    if t_ns < previous_ns:
        raise time_went_back(t_ns, previous_ns)
    return t_ns


def time_went_back(t_ns: int, previous_ns: int) -> RecordError:
    """The error for a cycle begun at ``t_ns``, before ``previous_ns``."""
    return RecordError(
        f"cycle time {t_ns} ns is earlier than {previous_ns} ns, the previous cycle's "
        "(or 0 before the first): time must not go backwards (PROFILE section 4)"
    )


class CycleSink(Protocol):
    """What a ``CycleBuilder`` hands its cycle to: the logger, or a test capture."""

    def _next_sensor_sequence(self, topic: str) -> int: ...
    def _commit(self, builder: CycleBuilder, started_ns: int | None) -> None: ...
    def _abort(self, builder: CycleBuilder) -> None: ...


class CycleBuilder:
    """One decision cycle being assembled; commit it once, or let ``with`` do it."""

    __slots__ = ("_committed", "_cost_ns", "_layers", "_logger", "_sensors", "cycle", "t_ns")

    def __init__(self, logger: CycleSink, cycle: int, t_ns: int) -> None:
        self._logger = logger
        self.cycle = cycle
        self.t_ns = t_ns
        self._layers: dict[str, LayerValue] = {}
        self._sensors: list[tuple[str, int, int, bytes]] = []
        self._committed = False
        self._cost_ns = 0  # control-thread time spent in the logger for this cycle

    def sensor(self, topic: str, payload: Any, t_ns: int | None = None) -> EvidenceRef:
        """Log a sensor reading that evidence will point to; return its evidence ref.

        ``payload`` is a JSON-able object or bytes of JSON. The ref carries the topic, log
        time, per-topic sequence and the SHA-256 of the data, so it resolves and verifies.
        """
        if not topic.startswith(SENSOR_PREFIX):
            raise RecordError(f"sensor topic must start with {SENSOR_PREFIX!r}: {topic!r}")
        data = payload if isinstance(payload, bytes) else encode_json(payload)
        log_time = self.t_ns if t_ns is None else t_ns
        sequence = self._logger._next_sensor_sequence(topic)
        self._sensors.append((topic, sequence, log_time, data))
        fields = {
            "topic": topic,
            "log_time_ns": log_time,
            "sequence": sequence,
            "digest": digest_keeping_gil(data),
        }
        try:
            # pydantic's validator itself: the same model as EvidenceRef(**fields), without
            # the two Python-level __init__ frames around it (~1 us of a ~10 us cycle)
            ref: EvidenceRef = _validate_evidence_ref(fields)
        except ValidationError:
            ref = validate_record(EvidenceRef, fields)  # raises RecordError, with its message
        return ref

    def perception(self, record: Any) -> None:
        """Add layer 1 (a ``Perception`` or a dict of its fields)."""
        self._add(TOPIC_PERCEPTION, record)

    def belief(self, record: Any) -> None:
        """Add layer 2 (a ``Belief`` or a dict of its fields)."""
        self._add(TOPIC_BELIEF, record)

    def action(self, record: Any) -> None:
        """Add layer 3 (an ``Action`` or a dict of its fields)."""
        self._add(TOPIC_ACTION, record)

    def execution(self, record: Any) -> None:
        """Add layer 4 (an ``Execution`` or a dict of its fields)."""
        self._add(TOPIC_EXECUTION, record)

    def _add(self, topic: str, record: Any) -> None:
        if self._committed:
            raise UsageError(f"cycle {self.cycle} is already committed")
        if topic in self._layers:
            raise UsageError(f"cycle {self.cycle} already has a {topic} record")
        self._layers[topic] = check_layer(LAYER_MODELS[topic], self.cycle, self.t_ns, record)

    def commit(self) -> None:
        """Hand the cycle to the writer. Never raises because of I/O."""
        if self._committed:
            raise UsageError(f"cycle {self.cycle} is already committed")
        self._committed = True
        self._logger._commit(self, None)

    def abort(self) -> None:
        """Give the cycle up; it is counted as dropped and the next seal says so."""
        if not self._committed:
            self._committed = True
            self._logger._abort(self)

    def __enter__(self) -> CycleBuilder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            if not self._committed:
                self.commit()
        else:
            self.abort()


class _TimedCycleBuilder(CycleBuilder):
    """A cycle whose logger calls are timed for ``trace.timing`` (trace_runtime.costs).

    One cycle in ``COST_SAMPLE_EVERY`` is timed: a clock read costs ~0.1 us, and timing every
    call of every cycle added ~12 % to a cycle of built records (bench/bench_logger.py).
    The rest are plain ``CycleBuilder``s and pay nothing for it.
    """

    __slots__ = ()

    def sensor(self, topic: str, payload: Any, t_ns: int | None = None) -> EvidenceRef:
        start = perf_counter_ns()
        # Forward the arguments as given: a wrapper of CycleBuilder.sensor (a test's tap)
        # then sees the same call from a timed cycle as from any other.
        if t_ns is None:
            ref = super().sensor(topic, payload)
        else:
            ref = super().sensor(topic, payload, t_ns)
        self._cost_ns += perf_counter_ns() - start
        return ref

    def _add(self, topic: str, record: Any) -> None:
        start = perf_counter_ns()
        super()._add(topic, record)
        self._cost_ns += perf_counter_ns() - start

    def commit(self) -> None:
        start = perf_counter_ns()
        if self._committed:
            raise UsageError(f"cycle {self.cycle} is already committed")
        self._committed = True
        self._logger._commit(self, start)


COST_SAMPLE_EVERY = 8
"""Cycles whose numbers are a multiple of this are timed for ``trace.timing``."""
_UNTIMED = COST_SAMPLE_EVERY - 1  # a power of two: number & _UNTIMED is 0 for timed cycles


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
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", robot_id):
            raise UsageError(f"robot_id must be a simple name (letters, digits, _.-): {robot_id!r}")
        if not period_s * 1e9 >= MIN_PERIOD_NS:  # also refuses NaN
            raise UsageError(
                f"period_s must be at least {MIN_PERIOD_NS / 1e9:g} s (PROFILE section 2), "
                f"got {period_s}"
            )
        self.config = config or LoggerConfig()
        interval = self.config.checkpoint_interval_s
        if interval is not None and interval <= 0:
            raise UsageError(f"checkpoint_interval_s must be positive or None, got {interval}")
        # A bad key file is a set-up error the integrator must see: it raises here.
        key = self.config.checkpoint_key
        self._signer: Signer | None = load_signer(key) if isinstance(key, str | Path) else key
        self.path = Path(path)
        self.is_root = self.path.suffix != ".mcap"
        self.stats = LoggerStats()
        self._opener = self.config.opener or _default_opener
        self._lock = threading.Lock()
        self._closed = False
        self._open_cycle: CycleBuilder | None = None
        self._last_t_ns = 0  # time of the last cycle begun (control thread only)
        self._sensor_seq: dict[str, int] = {}
        # Drops are declared by the seal of the next cycle written after them. The control
        # thread counts what it drops before the hand-over; the writer counts failed writes.
        self._undeclared_control = 0  # control thread only
        self._undeclared_writer = 0  # writer side only (under _lock)
        self._reported: set[str] = set()
        self._last_sync = time.monotonic()
        # close() giving up on a hung writer, and the writer finishing a batch after that,
        # settle ``stats.dropped_undelivered`` under this lock (see close()).
        self._accounting = threading.Lock()
        self._gave_up = False
        self._closing_cycles = 0  # threaded=False: cycles close() handed to the closer

        # One live writer per robot and log root: taken before reading the resume point, so
        # two processes cannot both continue the same chain. Raises LogLockedError.
        self._writer_lock = _WriterLock.take(_lock_path(self.path, self.is_root, robot_id))
        try:
            self._start(robot_id, period_s, software_version, policy_version, clock)
        except BaseException:
            if self._writer_lock is not None:
                self._writer_lock.release()
            raise

    def _start(
        self,
        robot_id: str,
        period_s: float,
        software_version: str,
        policy_version: str,
        clock: str,
    ) -> None:
        first_cycle, prev_seal, segment_no = 0, GENESIS, 0
        if self.is_root:
            first_cycle, prev_seal, segment_no = _resume_point(self.path, robot_id)
        self._next_cycle = first_cycle
        self._prev_seal = prev_seal
        self._session = SessionInfo(
            robot_id=robot_id,
            period_ns=round(period_s * 1e9),
            software_version=software_version,
            policy_version=policy_version,
            clock=clock,
            segment=segment_no,
            prev_seal=prev_seal,
            first_cycle=first_cycle,
        )
        self._segment: SegmentWriter | None = None
        self._segment_start_ns: int | None = None
        self._head: tuple[int, int] | None = None  # (cycle, t_ns) of the segment's last seal
        self._sealed_in_segment = 0
        self._checkpoint_due_ns: int | None = None  # log time the next periodic one is due
        self._costs = CostHistogram()  # this segment's per-cycle control-thread costs
        # Opening the first segment may fail (bad path, no permission): that is a set-up
        # error the integrator must see, so it raises here, unlike every later I/O failure.
        self._open_segment(self._session)

        self._sync_batch: list[_PendingCycle] = []  # threaded=False, batch_cycles > 1
        self._queue: _Handover | None = None
        self._thread: threading.Thread | None = None
        if self.config.threaded:
            self._queue = _Handover(self.config.queue_cycles)
            self._thread = threading.Thread(
                target=self._run_writer, name=f"trace-writer-{robot_id}", daemon=True
            )
            self._thread.start()

    # --- control-thread API -------------------------------------------------------------

    def cycle(self, t_ns: int | None = None) -> CycleBuilder:
        """Begin the next decision cycle at ``t_ns`` (default: now, wall clock).

        Raises ``RecordError`` when ``t_ns`` is earlier than the previous cycle's time
        (PROFILE §4: time does not go backwards within a session); the cycle number is then
        not used.
        """
        if self._closed:
            raise UsageError("the logger is closed")
        if self._open_cycle is not None and not self._open_cycle._committed:
            raise UsageError(f"cycle {self._open_cycle.cycle} was begun but not committed")
        # next_cycle_time()'s rule, inlined: this runs every cycle on the control thread.
        if t_ns is None:
            t_ns = time.time_ns()
        elif t_ns < self._last_t_ns:
            raise time_went_back(t_ns, self._last_t_ns)
        self._last_t_ns = t_ns
        number = self._next_cycle
        builder = (CycleBuilder if number & _UNTIMED else _TimedCycleBuilder)(self, number, t_ns)
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

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until every committed cycle has been written; True if it got there."""
        if self._queue is None:
            return True
        return self._queue.wait_idle(timeout_s)

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
        if self._queue is not None and self._thread is not None:
            self._queue.close()
            finisher = self._thread
        else:
            batch, self._sync_batch = self._sync_batch, []
            self._closing_cycles = len(batch)
            finisher = threading.Thread(
                target=self._finish,
                args=(batch,),
                name=f"trace-close-{self._session.robot_id}",
                daemon=True,
            )
            finisher.start()
        finisher.join(timeout_s)
        if timeout_s is not None and finisher.is_alive():
            self._give_up(timeout_s)

    def _give_up(self, timeout_s: float) -> None:
        """close() timed out: count what the writer still holds as undelivered."""
        with self._accounting:
            self._gave_up = True
            if self._queue is not None:
                self._queue.abandon()
                undelivered = self._queue.undone
            else:
                undelivered = self._closing_cycles
            self.stats.dropped_undelivered += undelivered
        self._report_once(
            "close-timeout",
            f"audit log close timed out after {timeout_s:g} s (storage hung?): "
            f"{undelivered} cycle(s) not written",
        )

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
        pending = _PendingCycle(
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
            self._sync_batch.append(pending)
            if len(self._sync_batch) >= self.config.batch_cycles:
                batch, self._sync_batch = self._sync_batch, []
                with self._lock:
                    self._write_batch(batch)
            return
        if self._queue.put(pending, block=self.config.when_full == "block"):
            self._undeclared_control = 0
        else:
            self.stats.dropped_queue_full += 1
            self._undeclared_control += 1
            self._report_once("queue", "audit queue full: dropping cycles (writer too slow)")

    def _abort(self, builder: CycleBuilder) -> None:
        self.stats.dropped_aborted += 1
        self._undeclared_control += 1

    # --- writer side --------------------------------------------------------------------

    def _run_writer(self) -> None:
        handover = self._queue
        assert handover is not None
        while True:
            batch = handover.take(self.config.max_batch_cycles)
            if not batch:
                break  # closed and drained, or abandoned by a close() that timed out
            with self._lock:
                self._write_batch(batch)
            with self._accounting:
                handover.done(len(batch))
                if self._gave_up:  # close() counted this batch as undelivered; it is not
                    self.stats.dropped_undelivered -= len(batch)
        # What close() took out of the queue is declared in trace.close like any drop.
        skipped = handover.discarded
        self._finish([], skipped=len(skipped) + sum(p.dropped_before for p in skipped))

    def _finish(self, batch: list[_PendingCycle], *, skipped: int = 0) -> None:
        """End the log: write ``batch``, declare the undeclared tail, close the segment, let
        go of the writer lock. On the writer thread, or a closer thread (threaded=False)."""
        try:
            with self._lock:
                if batch:
                    self._write_batch(batch)
                    with self._accounting:
                        if self._gave_up:
                            self.stats.dropped_undelivered -= len(batch)
                        self._closing_cycles = 0
                self._undeclared_writer += skipped
                self._check_storage()
                self._declare_tail()
                self._close_segment()
        finally:
            if self._writer_lock is not None:
                self._writer_lock.release()

    def _write_batch(self, batch: list[_PendingCycle]) -> None:
        """Seal and write cycles; called with ``_lock`` held. Swallows every failure."""
        try:
            self._check_storage()
            self._maybe_rotate(batch[0].t_ns)
            if self._segment is None:
                self._open_segment(self._session.next_segment(self._prev_seal, batch[0].cycle))
            segment = self._segment
            if segment is None:
                raise SegmentWriteError("no segment could be opened", rolled_back=False)
            messages, last_seal, checkpoints = self._seal(segment, batch)
            self.stats.bytes_written += segment.write_batch(messages)
        except SegmentWriteError as err:
            self._lose(batch, err, abandon=not err.rolled_back)
            return
        except Exception as err:
            self._lose(batch, err, abandon=True)
            return
        self._prev_seal = last_seal
        self._undeclared_writer = 0
        self.stats.written += len(batch)
        self._head = (batch[-1].cycle, batch[-1].t_ns)
        self._sealed_in_segment += len(batch)
        self.stats.checkpoints += checkpoints
        if self._segment_start_ns is None:
            self._segment_start_ns = batch[0].t_ns
        for pending in batch:
            if pending.cost_ns >= 0:  # -1: not a timed cycle
                self._costs.add(pending.cost_ns)
        self._maybe_sync()

    def _seal(
        self, segment: SegmentWriter, batch: list[_PendingCycle]
    ) -> tuple[list[MessageFields], str, int]:
        """The batch's messages in file order, the last seal's digest, and how many periodic
        checkpoints are among the messages (each right after the seal it names).

        Messages are plain tuples and the channel ids are looked up once per batch: this
        loop runs five or more times per cycle on the writer, holding the GIL."""
        messages: list[MessageFields] = []
        append = messages.append
        checkpoints = 0
        prev = self._prev_seal
        carried = self._undeclared_writer
        channel = segment.channel
        layer_channels = {topic: channel(topic) for topic in LAYER_MODELS}
        seal_channel = channel(TOPIC_SEAL)
        for index, pending in enumerate(batch):
            cycle, t_ns = pending.cycle, pending.t_ns
            for topic, sequence, log_time, data in pending.sensors:
                append((channel(topic), sequence, log_time, data))
            digests: dict[str, str] = {}
            for topic, record in pending.layers.items():
                if isinstance(record, EncodedLayer):  # a dict, encoded on the control thread
                    data, digests[topic] = record
                else:
                    data = encode_layer(cycle, t_ns, record, LAYER_MODELS[topic])
                    digests[topic] = digest_keeping_gil(data)
                append((layer_channels[topic], cycle, t_ns, data))
            data = encode_seal_fields(cycle, t_ns, digests, prev, carried + pending.dropped_before)
            append((seal_channel, cycle, t_ns, data))
            prev = digest(data)
            carried = 0
            if self._checkpoint_due(t_ns):
                sealed = self._sealed_in_segment + index + 1
                checkpoint = self._checkpoint_message(
                    segment, cycle, t_ns, prev, sealed, final=False
                )
                if checkpoint is not None:
                    append(checkpoint)
                    checkpoints += 1
        return messages, prev, checkpoints

    def _lose(self, batch: list[_PendingCycle], err: Exception, *, abandon: bool) -> None:
        self.stats.dropped_io += len(batch)
        self._undeclared_writer += len(batch) + sum(p.dropped_before for p in batch)
        self._report_once(f"io:{type(err).__name__}", f"audit write failed, dropping cycles: {err}")
        if abandon and self._segment is not None:
            # The file cannot be trusted past its last good batch; readers recover up to it.
            with contextlib.suppress(Exception):  # already failing; nothing more to do
                self._segment._stream.close()
            self._segment = None

    def _check_storage(self) -> None:
        """A segment deleted under the writer (its directory removed) is lost with every
        cycle sealed into it: give it up so the next batch opens a new segment (recreating
        the directory) that continues the chain from the last seal, and whose first seal
        declares the lost cycles as dropped (schemas/PROFILE.md §7). One fstat per batch."""
        segment = self._segment
        if segment is None or not segment.storage_lost():
            return
        lost = self._sealed_in_segment
        self.stats.written -= lost
        self.stats.dropped_storage_lost += lost
        self._undeclared_writer += lost
        path = self.stats.segments[-1] if self.stats.segments else self.path
        self._report_once(
            "storage",
            f"audit storage lost: {path} was deleted under the writer with {lost} cycle(s); "
            "going on in a new segment",
        )
        with contextlib.suppress(OSError, ValueError):  # nothing to save in an unlinked file
            segment._stream.close()
        self._segment = None
        if self._writer_lock is not None:
            self._writer_lock.renew(self._report_once)

    def _maybe_rotate(self, t_ns: int) -> None:
        segment = self._segment
        if segment is None or not self.is_root or self._segment_start_ns is None:
            return
        too_long = t_ns - self._segment_start_ns >= self.config.max_segment_s * 1e9
        if too_long or segment.offset >= self.config.max_segment_bytes:
            self._close_segment()

    def _open_segment(self, session: SessionInfo) -> None:
        path = self._segment_path(session)
        path.parent.mkdir(parents=True, exist_ok=True)
        stream = self._opener(path)
        try:
            segment = SegmentWriter(stream, session, level=self.config.compression_level)
        except BaseException:
            with contextlib.suppress(Exception):  # the header failed; the file is given up
                stream.close()
            raise
        self._segment = segment
        self._session = session
        self._segment_start_ns = None
        self._head = None
        self._sealed_in_segment = 0
        self._checkpoint_due_ns = None
        self._costs = CostHistogram()
        self.stats.segments.append(path)

    def _declare_tail(self) -> None:
        """Drops after the last seal have no next seal to declare them: say so at close in a
        ``trace.close`` metadata record (schemas/PROFILE.md §7), so the gap is not silent."""
        tail = self._undeclared_control + self._undeclared_writer
        segment = self._segment
        if tail == 0 or segment is None or segment.broken:
            return
        last = self._head[0] if self._head is not None else self._session.first_cycle - 1
        try:
            segment.add_metadata(
                CLOSE_METADATA,
                {"dropped_after_last_seal": str(tail), "last_sealed_cycle": str(last)},
            )
        except Exception as err:
            self._report_once("close", f"could not record the dropped tail: {err}")

    def _close_segment(self) -> None:
        segment, self._segment = self._segment, None
        if segment is None:
            return
        if self._head is not None and not segment.broken:
            # The closing checkpoint: a finished segment without one was cut (docs/integrity.md).
            cycle, t_ns = self._head
            message = self._checkpoint_message(
                segment, cycle, t_ns, self._prev_seal, self._sealed_in_segment, final=True
            )
            if message is not None:
                try:
                    self.stats.bytes_written += segment.write_batch([message])
                    self.stats.checkpoints += 1
                except Exception as err:
                    self.stats.checkpoint_failures += 1
                    self._report_once("checkpoint", f"could not write a checkpoint: {err}")
        if self._costs.cycles and not segment.broken:
            # The logger's own cost per cycle, for Table II of `trace-audit metrics`.
            try:
                segment.add_metadata(TIMING_METADATA, self._costs.to_metadata(COST_SAMPLE_EVERY))
            except Exception as err:
                self._report_once("timing", f"could not record the logger's cost: {err}")
        try:
            segment.close()
        except Exception as err:
            self._report_once("close", f"could not finish segment: {err}")

    def _segment_path(self, session: SessionInfo) -> Path:
        if not self.is_root:
            if session.segment == 0 or not self.stats.segments:
                return self.path
            return self.path.with_name(f"{self.path.stem}.{session.segment:06d}.mcap")
        return self.path / "hot" / f"{session.robot_id}_{session.segment:06d}.mcap"

    def _checkpoint_due(self, t_ns: int) -> bool:
        """Whether a periodic checkpoint goes after the seal of the cycle at ``t_ns``.

        They fall on a grid in log time: the first seal at or past each multiple of the
        interval from the segment's first cycle, so their spacing does not depend on how
        cycles were batched into chunks. After a pause longer than the interval there is one
        checkpoint, not one per missed multiple. A checkpoint that could not be built or
        signed still counts as done: a signer that is down (an HSM that times out) is asked
        again an interval later, not on every cycle.
        """
        interval = self.config.checkpoint_interval_s
        if interval is None:
            return False
        step = max(1, round(interval * 1e9))
        due = self._checkpoint_due_ns
        if due is None:
            start = t_ns if self._segment_start_ns is None else self._segment_start_ns
            due = self._checkpoint_due_ns = start + step
        if t_ns < due:
            return False
        self._checkpoint_due_ns = due + ((t_ns - due) // step + 1) * step
        return True

    def _checkpoint_message(
        self,
        segment: SegmentWriter,
        cycle: int,
        t_ns: int,
        head: str,
        sealed: int,
        *,
        final: bool,
    ) -> OutMessage | None:
        """Build (and sign) a checkpoint message; None if that fails: never raises.

        When signing fails (an HSM gone) the checkpoint is written unsigned: it still
        anchors the chain head and marks a closed segment, and verify reports it unsigned.
        """
        build = functools.partial(
            make_checkpoint,
            robot_id=self._session.robot_id,
            segment=self._session.segment,
            first_cycle=self._session.first_cycle,
            cycle=cycle,
            t_ns=t_ns,
            sealed=sealed,
            head=head,
            final=final,
        )
        try:
            try:
                checkpoint = build(signer=self._signer)
            except Exception as err:
                if self._signer is None:
                    raise
                self.stats.checkpoint_failures += 1
                self._report_once("sign", f"could not sign a checkpoint, wrote it unsigned: {err}")
                checkpoint = build()
            data = encode_checkpoint(checkpoint)
            return OutMessage(segment.channel(TOPIC_CHECKPOINT), cycle, t_ns, data)
        except Exception as err:  # the audit trail goes on without this checkpoint
            self.stats.checkpoint_failures += 1
            self._report_once("checkpoint", f"could not build a checkpoint: {err}")
            return None

    def _maybe_sync(self) -> None:
        interval = self.config.fsync_interval_s
        if interval is None or self._segment is None:
            return
        now = time.monotonic()
        if now - self._last_sync >= interval:
            self._last_sync = now
            try:
                self._segment.sync()
            except OSError as err:
                self._report_once("fsync", f"fsync failed: {err}")

    def _report_once(self, kind: str, message: str) -> None:
        if kind not in self._reported:
            self._reported.add(kind)
            log.warning("%s (reported once; see AuditLogger.stats)", message)


def _resume_point(root: Path, robot_id: str) -> tuple[int, str, int]:
    """(next cycle, last seal digest, next segment number) after the robot's newest segment.

    Segments move from ``hot/`` to ``warm/`` and ``cold/`` as they age (trace_runtime.tiers),
    so all three are searched: the highest segment number wins, wherever it lives.
    """
    name = re.compile(re.escape(robot_id) + r"_(\d+)\.mcap")
    numbered: list[tuple[int, int, Path]] = []
    for rank, tier in enumerate(TIERS):
        directory = root / tier
        if directory.is_dir():
            for path in directory.glob(f"{robot_id}_*.mcap"):
                match = name.fullmatch(path.name)
                if match:
                    # A segment in two tiers (mid-compaction): the less compacted copy first.
                    numbered.append((int(match.group(1)), -rank, path))
    if not numbered:
        return 0, GENESIS, 0
    from trace_runtime.reader import last_seal  # deferred: the reader is not needed otherwise

    numbered.sort()
    number = numbered[-1][0]
    # The chain continues from the newest seal on disk. A segment a crash left without any
    # seal (killed before its first write) is skipped, so the chain does not restart.
    for _number, _rank, path in reversed(numbered):
        found = last_seal(path)
        if found is not None:
            seal, seal_digest = found
            return seal.cycle + 1, seal_digest, number + 1
    return 0, GENESIS, number + 1


def _lock_path(path: Path, is_root: bool, robot_id: str) -> Path:
    """Where the writer lock of a log lives: per robot in a root, per file otherwise. A file
    written straight into a root's tier directory takes the robot's root lock: it would
    otherwise fork the chain of a logger writing that root."""
    if is_root:
        return path / ".locks" / f"{robot_id}.lock"
    if path.parent.name in TIERS:
        return path.parent.parent / ".locks" / f"{robot_id}.lock"
    return path.with_name(f".{path.name}.lock")


class _WriterLock:
    """One live writer per robot and log root: an exclusive ``flock`` on a lock file.

    The kernel drops the lock when the process dies, so ``kill -9`` never leaves a stale
    one. The holder's pid is written into the file for the refusal message. ``flock``
    locks belong to the open file, so a second logger in the same process is refused too.
    """

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd = fd

    @classmethod
    def take(cls, path: Path) -> _WriterLock | None:
        """Lock ``path``; raise ``LogLockedError`` when another writer holds it. None where
        the platform or the filesystem has no ``flock`` (logged; the log is then unguarded)."""
        if sys.platform == "win32":
            return None
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_pid(fd)
            os.close(fd)
            raise LogLockedError(str(path), holder) from None
        except OSError as err:  # e.g. ENOLCK on a filesystem without locks
            os.close(fd)
            log.warning("cannot lock %s (%s): a second writer would not be refused", path, err)
            return None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError:
            pass  # the pid is only for the message; the lock itself holds
        return cls(path, fd)

    def renew(self, report: Callable[[str, str], None]) -> None:
        """The lock file was deleted with its directory: lock a new one at the same place,
        so a logger started on the recreated root is still refused."""
        if self._fd < 0:
            return
        try:
            if os.fstat(self._fd).st_nlink > 0:
                return
            fresh = _WriterLock.take(self.path)
        except LogLockedError as err:
            report("lock", f"audit log lock lost with its directory and taken by another: {err}")
            return
        except OSError as err:
            report("lock", f"could not renew the audit log lock {self.path}: {err}")
            return
        if fresh is not None:
            os.close(self._fd)
            self._fd, fresh._fd = fresh._fd, -1

    def release(self) -> None:
        """Let go of the lock (closing the descriptor drops it). Idempotent."""
        fd, self._fd = self._fd, -1
        if fd < 0:
            return
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)  # no stale pid for the next reader
        os.close(fd)


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None
