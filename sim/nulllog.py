"""A logger that records nothing: the control-loop API of ``AuditLogger`` with no-op calls.

It exists to measure what audit logging costs. The simulator runs the same cycles, seeds
and record assembly with it as with ``AuditLogger``; the difference in time per cycle is the
logger's own work (validation, canonical encoding, digests, sealing, writing).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import TracebackType
from typing import Any

from trace_runtime import LoggerStats

__all__ = ["NullCycle", "NullLogger", "NullRef"]


@dataclass(frozen=True, slots=True)
class NullRef:
    """Where a reading would have been logged; nothing was (no sequence, no digest)."""

    topic: str
    log_time_ns: int
    sequence: None = None
    digest: None = None


class NullCycle:
    """One cycle handed to nobody: every layer call returns at once."""

    __slots__ = ("_stats", "cycle", "t_ns")

    def __init__(self, stats: LoggerStats, cycle: int, t_ns: int) -> None:
        self._stats = stats
        self.cycle = cycle
        self.t_ns = t_ns

    def sensor(self, topic: str, payload: Any, t_ns: int | None = None) -> NullRef:
        """Keep nothing; give the bare ref the robot's records carry (no encoding, no digest)."""
        return NullRef(topic, self.t_ns if t_ns is None else t_ns)

    def perception(self, record: Any) -> None:
        return None

    def belief(self, record: Any) -> None:
        return None

    def action(self, record: Any) -> None:
        return None

    def execution(self, record: Any) -> None:
        return None

    def __enter__(self) -> NullCycle:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        # Counted as written so a caller that settles its own bookkeeping on the logger's
        # counters (the simulator's ground truth) sees every cycle as handled.
        if exc_type is None:
            self._stats.committed += 1
            self._stats.written += 1


class NullLogger:
    """Stands in for ``AuditLogger`` in the control loop and writes nothing."""

    def __init__(self) -> None:
        self.stats = LoggerStats()
        self._next = 0

    def cycle(self, t_ns: int) -> NullCycle:
        c = NullCycle(self.stats, self._next, t_ns)
        self._next += 1
        return c

    def close(self) -> None:
        return None
