"""The bounded hand-over of committed cycles from a robot's control thread to the writer.

Neither thread lets go of the GIL per message: a thread that lets go waits up to the switch
interval (5 ms) to get it back from a busy one, so a writer that let go once per message
(``hashlib`` does, for data of 2 KiB and more) starved behind a control thread validating
dicts (docs/performance.md). The hand-over therefore costs the control thread a ``deque``
append and, only when the writer sleeps, one C-level lock release (``Wakeup``).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from trace_runtime.encoding.codec import LayerValue

__all__ = ["Handover", "PendingCycle", "SensorReading", "Wakeup"]

SensorReading = tuple[str, int, int, bytes, str]
"""A sensor reading on its way to the writer: topic, sequence, log time, data, and the
SHA-256 hex of the data (hashed once, on the control thread, for its evidence ref)."""


@dataclass(slots=True)
class PendingCycle:
    """A committed cycle on its way to the writer: its layers, sensor readings, the drops
    before it that its seal declares, and the control-thread cost (-1: not timed)."""

    cycle: int
    t_ns: int
    layers: dict[str, LayerValue]
    sensors: list[SensorReading]
    dropped_before: int
    cost_ns: int


class Wakeup:
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


class Handover:
    """The bounded hand-over from the control thread to the writer thread.

    One producer, one consumer. ``collections.deque`` appends and pops are atomic, so the
    control thread pays for an append and, when the writer sleeps, a lock release: not for
    a lock-guarded ``queue.Queue`` nor an ``Event``. Each counter is written by one thread.
    """

    def __init__(self, bound: int) -> None:
        self._items: deque[PendingCycle] = deque()
        self._bound = bound
        self._wake = Wakeup()
        self._space = threading.Event()
        self._closed = False
        self._put = 0  # producer only
        self._done = 0  # consumer only
        self.discarded: list[PendingCycle] = []  # what abandon() took out, never written

    def put(self, item: PendingCycle, *, block: bool) -> bool:
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

    def take(self, most: int) -> list[PendingCycle]:
        """Up to ``most`` items, waiting for at least one; [] once closed and drained."""
        while True:
            batch: list[PendingCycle] = []
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
