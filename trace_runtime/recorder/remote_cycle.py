"""What a ``RemoteLogger`` hands the control loop: ``RemoteCycle``, a decision cycle being
assembled with ``CycleBuilder``'s calls, and ``RemoteStats``, the client's counters.

The builder only keeps references and checks what costs nothing to check (a layer given
twice, a record of the wrong type, a sensor topic): the records themselves are checked by
the recorder, with the logger's own models.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import TracebackType
from typing import Any, Protocol

import orjson

from trace_runtime.errors import RecordError, UsageError
from trace_runtime.records import (
    LAYER_MODELS,
    SENSOR_PREFIX,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    EvidenceRef,
)

__all__ = ["RemoteCycle", "RemoteStats"]

_LAYER_NAMES = {
    TOPIC_PERCEPTION: "perception",
    TOPIC_BELIEF: "belief",
    TOPIC_ACTION: "action",
    TOPIC_EXECUTION: "execution",
}


class _Sink(Protocol):
    """What a ``RemoteCycle`` hands its cycle to (the ``RemoteLogger``)."""

    stats: RemoteStats

    def _commit(self, builder: RemoteCycle) -> None: ...


@dataclass(slots=True)
class RemoteStats:
    """Counters a robot can export to its health monitoring."""

    committed: int = 0
    sent: int = 0
    """Cycles handed to the socket (the recorder may still refuse one: ``refused``)."""
    dropped_queue_full: int = 0
    dropped_disconnected: int = 0
    """Cycles committed while no recorder was connected."""
    dropped_unsent: int = 0
    """Cycles queued when the connection was lost (each counter has one writing thread)."""
    dropped_aborted: int = 0
    refused: int = 0
    """Frames the recorder answered with an error (a bad record, time going back)."""
    connects: int = 0
    """Successful hellos: 1, plus one per reconnection."""
    last_error: str = ""

    @property
    def dropped(self) -> int:
        return (
            self.dropped_queue_full
            + self.dropped_disconnected
            + self.dropped_unsent
            + self.dropped_aborted
        )


class RemoteCycle:
    """One decision cycle being assembled; the same calls as ``CycleBuilder``.

    ``cycle`` is this cycle's number on this client (from 0); the recorder numbers the
    cycles of the log, continuing the robot's chain.
    """

    __slots__ = ("_committed", "_layers", "_logger", "_sensors", "cycle", "t_ns")

    def __init__(self, logger: _Sink, cycle: int, t_ns: int) -> None:
        self._logger = logger
        self.cycle = cycle
        self.t_ns = t_ns
        self._layers: dict[str, Any] = {}
        self._sensors: list[tuple[str, Any, int]] = []
        self._committed = False

    def sensor(self, topic: str, payload: Any, t_ns: int | None = None) -> EvidenceRef:
        """Send a sensor reading with this cycle; return an evidence ref to it (topic and
        log time: the recorder adds the sequence and digest it gives the reading)."""
        if not topic.startswith(SENSOR_PREFIX):
            raise RecordError(f"sensor topic must start with {SENSOR_PREFIX!r}: {topic!r}")
        log_time = self.t_ns if t_ns is None else t_ns
        data = orjson.Fragment(payload) if isinstance(payload, bytes) else payload
        self._sensors.append((topic, data, log_time))
        return EvidenceRef(topic=topic, log_time_ns=log_time)

    def perception(self, record: Any) -> None:
        self._add(TOPIC_PERCEPTION, record)

    def belief(self, record: Any) -> None:
        self._add(TOPIC_BELIEF, record)

    def action(self, record: Any) -> None:
        self._add(TOPIC_ACTION, record)

    def execution(self, record: Any) -> None:
        self._add(TOPIC_EXECUTION, record)

    def _add(self, topic: str, record: Any) -> None:
        if self._committed:
            raise UsageError(f"cycle {self.cycle} is already committed")
        name = _LAYER_NAMES[topic]
        if name in self._layers:
            raise UsageError(f"cycle {self.cycle} already has a {topic} record")
        if not isinstance(record, LAYER_MODELS[topic] | dict):
            raise RecordError(
                f"{topic}: expected a {LAYER_MODELS[topic].__name__} or a dict, "
                f"got {type(record).__name__}"
            )
        self._layers[name] = record

    def commit(self) -> None:
        """Queue the cycle for the sender; never waits, never raises because of I/O."""
        if self._committed:
            raise UsageError(f"cycle {self.cycle} is already committed")
        self._committed = True
        self._logger._commit(self)

    def abort(self) -> None:
        """Give the cycle up; it is counted as dropped and declared with the next one."""
        if not self._committed:
            self._committed = True
            self._logger.stats.dropped_aborted += 1

    def __enter__(self) -> RemoteCycle:
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
