"""Test helpers for robots that embed the logger: capture cycles in memory, no files.

    from trace_runtime.testing import CaptureLogger

    def test_my_robot_stops_for_people():
        log = CaptureLogger(robot_id="amr-test")
        run_my_control_loop(log, steps=10)       # the robot calls log.cycle() as usual
        assert log.cycles[-1].action.command == "STOP"
        assert log.cycles[-1].seal.prev == log.cycles[-2].seal_digest

``CaptureLogger`` offers the control-loop API of ``AuditLogger`` (``cycle()``/``begin()``,
``log_cycle()``, ``close()``, ``stats``) and runs the same validation and the same canonical
encoding and sealing, so what a test sees is exactly what would have been written.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, TypeVar

from trace_runtime.chain import digest
from trace_runtime.codec import encode_layer, encode_seal
from trace_runtime.errors import UsageError
from trace_runtime.logger import CycleBuilder, LoggerStats
from trace_runtime.records import (
    GENESIS,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    Action,
    Belief,
    Execution,
    Perception,
    Seal,
)


@dataclass(slots=True)
class CapturedSensor:
    topic: str
    sequence: int
    log_time_ns: int
    data: bytes


@dataclass(slots=True)
class CapturedCycle:
    """One committed cycle: the records as handed over, their canonical bytes and the seal."""

    cycle: int
    t_ns: int
    perception: Perception | None
    belief: Belief | None
    action: Action | None
    execution: Execution | None
    sensors: list[CapturedSensor]
    payloads: dict[str, bytes]
    seal: Seal
    seal_digest: str


@dataclass
class CaptureLogger:
    """An in-memory stand-in for ``AuditLogger`` with the same control-loop API."""

    robot_id: str = "test-robot"
    period_s: float = 0.1
    cycles: list[CapturedCycle] = field(default_factory=list)
    stats: LoggerStats = field(default_factory=LoggerStats)
    _next_cycle: int = 0
    _prev_seal: str = GENESIS
    _dropped_since_seal: int = 0
    _sensor_seq: dict[str, int] = field(default_factory=dict)
    _open: CycleBuilder | None = None
    _closed: bool = False

    def cycle(self, t_ns: int | None = None) -> CycleBuilder:
        """Begin the next cycle (default time: now)."""
        if self._closed:
            raise UsageError("the logger is closed")
        if self._open is not None and not self._open._committed:
            raise UsageError(f"cycle {self._open.cycle} was begun but not committed")
        builder = CycleBuilder(self, self._next_cycle, time.time_ns() if t_ns is None else t_ns)
        self._next_cycle += 1
        self._open = builder
        return builder

    begin = cycle

    def log_cycle(self, t_ns: int | None = None, **layers: Any) -> int:
        """Log pre-built records in one call (``perception=``, ``belief=``, ...)."""
        with self.cycle(t_ns) as c:
            for name, record in layers.items():
                if record is not None:
                    getattr(c, name)(record)
        return c.cycle

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> CaptureLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def commands(self) -> list[str | None]:
        """The command of every captured cycle, in order (None where no action was given)."""
        return [c.action.command if c.action else None for c in self.cycles]

    # --- the CycleSink protocol ---------------------------------------------------------

    def _next_sensor_sequence(self, topic: str) -> int:
        seq = self._sensor_seq.get(topic, 0)
        self._sensor_seq[topic] = seq + 1
        return seq

    def _commit(self, builder: CycleBuilder) -> None:
        layers = builder._layers
        payloads = {
            topic: encode_layer(builder.cycle, builder.t_ns, record)
            for topic, record in layers.items()
        }
        seal = Seal(
            cycle=builder.cycle,
            t_ns=builder.t_ns,
            digests={topic: digest(data) for topic, data in payloads.items()},
            prev=self._prev_seal,
            dropped=self._dropped_since_seal,
        )
        seal_digest = digest(encode_seal(seal))
        sensors = [CapturedSensor(*sensor) for sensor in builder._sensors]
        self.cycles.append(
            CapturedCycle(
                cycle=builder.cycle,
                t_ns=builder.t_ns,
                perception=_typed(layers.get(TOPIC_PERCEPTION), Perception),
                belief=_typed(layers.get(TOPIC_BELIEF), Belief),
                action=_typed(layers.get(TOPIC_ACTION), Action),
                execution=_typed(layers.get(TOPIC_EXECUTION), Execution),
                sensors=sensors,
                payloads=payloads,
                seal=seal,
                seal_digest=seal_digest,
            )
        )
        self._prev_seal = seal_digest
        self._dropped_since_seal = 0
        self.stats.committed += 1
        self.stats.written += 1

    def _abort(self, builder: CycleBuilder) -> None:
        self.stats.dropped_aborted += 1
        self._dropped_since_seal += 1


T = TypeVar("T")


def _typed(record: object, kind: type[T]) -> T | None:
    return record if isinstance(record, kind) else None
