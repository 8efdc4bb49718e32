"""``CycleBuilder``: one decision cycle as the control loop assembles it.

A builder keeps a reference to each built record (an ``isinstance``), validates and encodes
a plain dict at once (``trace_runtime.encoding.codec.check_layer``), encodes the small sensor
payloads it needs digests for, and hands the cycle to its sink (the logger, or a test
capture) at ``commit``. One cycle in ``COST_SAMPLE_EVERY`` is a ``TimedCycleBuilder``, which
times the logger's own calls for ``trace.timing``.
"""

from __future__ import annotations

from time import perf_counter_ns
from types import TracebackType
from typing import Any, Protocol

from pydantic import ValidationError

from trace_runtime.encoding.codec import LayerValue, check_layer, digest_keeping_gil, encode_json
from trace_runtime.errors import RecordError, UsageError
from trace_runtime.logger.handover import SensorReading
from trace_runtime.record_model import validate_record
from trace_runtime.records import (
    LAYER_MODELS,
    SENSOR_PREFIX,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    EvidenceRef,
)

__all__ = [
    "COST_SAMPLE_EVERY",
    "UNTIMED",
    "CycleBuilder",
    "CycleSink",
    "TimedCycleBuilder",
]

_validate_evidence_ref = EvidenceRef.__pydantic_validator__.validate_python


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
        self._sensors: list[SensorReading] = []
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
        data_digest = digest_keeping_gil(data)
        self._sensors.append((topic, sequence, log_time, data, data_digest))
        fields = {
            "topic": topic,
            "log_time_ns": log_time,
            "sequence": sequence,
            "digest": data_digest,
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


class TimedCycleBuilder(CycleBuilder):
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
UNTIMED = COST_SAMPLE_EVERY - 1  # a power of two: number & UNTIMED is 0 for timed cycles
