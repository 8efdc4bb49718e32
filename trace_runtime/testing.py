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

import orjson

from trace_runtime.chain import digest, sensor_cover, sensor_line
from trace_runtime.encoding.codec import EncodedLayer, LayerValue, encode_checked, encode_seal
from trace_runtime.errors import RecordError, UsageError
from trace_runtime.logger.api import AuditLogger, LoggerStats
from trace_runtime.logger.cycle_builder import CycleBuilder
from trace_runtime.records import (
    GENESIS,
    LAYER_MODELS,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    Action,
    Alternative,
    Belief,
    BeliefEdge,
    BeliefNode,
    ComplianceCheck,
    Counterfactual,
    DecisionTree,
    Entity,
    Evidence,
    EvidenceRef,
    Execution,
    Factor,
    Motion,
    Perception,
    Pose,
    Rationale,
    Region,
    Seal,
    SensorCover,
    TreeEdge,
    TreeNode,
)


@dataclass(slots=True)
class CapturedSensor:
    topic: str
    sequence: int
    log_time_ns: int
    data: bytes
    digest: str
    """The SHA-256 hex of ``data``."""


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
    _last_t_ns: int = 0

    def cycle(self, t_ns: int | None = None) -> CycleBuilder:
        """Begin the next cycle (default time: now)."""
        if self._closed:
            raise UsageError("the logger is closed")
        if self._open is not None and not self._open._committed:
            raise UsageError(f"cycle {self._open.cycle} was begun but not committed")
        t_ns = time.time_ns() if t_ns is None else t_ns
        if t_ns < 0:
            raise RecordError(f"cycle time {t_ns} ns is negative (PROFILE section 4)")
        if t_ns < self._last_t_ns:  # a clock step: AuditLogger declares it in a new segment
            self.stats.clock_steps += 1
        self._last_t_ns = t_ns
        builder = CycleBuilder(self, self._next_cycle, t_ns)
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

    def _commit(self, builder: CycleBuilder, started_ns: int | None) -> None:
        layers = builder._layers
        payloads = {
            topic: encode_checked(builder.cycle, builder.t_ns, LAYER_MODELS[topic], record)
            for topic, record in layers.items()
        }
        count, readings_digest = sensor_cover(
            [sensor_line(topic, seq, at, hexed) for topic, seq, at, _, hexed in builder._sensors]
        )
        seal = Seal(
            cycle=builder.cycle,
            t_ns=builder.t_ns,
            digests={topic: digest(data) for topic, data in payloads.items()},
            prev=self._prev_seal,
            dropped=self._dropped_since_seal,
            sensors=SensorCover(count=count, digest=readings_digest),
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


T = TypeVar("T", Perception, Belief, Action, Execution)


def _typed(record: LayerValue | None, kind: type[T]) -> T | None:
    """The record as its model, also when the robot handed over a dict (then validated and
    encoded at the call site: the model is read back from the bytes that were written)."""
    if record is None or isinstance(record, kind):
        return record
    assert isinstance(record, EncodedLayer)
    fields = orjson.loads(record.data)
    del fields["cycle"], fields["t_ns"]
    return kind.model_validate(fields)


def synthetic_cycle(
    index: int, *, pedestrians: int = 2, ref_topic: str = "/sensors/lidar"
) -> tuple[Perception, Belief, Action, Execution]:
    """A plausible 3-5 KB decision cycle whose values drift smoothly with ``index``.

    For tests and benchmarks that need realistic records without running the simulator:
    ``pedestrians`` entities with evidence, a belief graph of distance and risk states, a
    STOP/SLOW/CONTINUE choice with alternatives, counterfactuals and a decision tree.
    """
    t_ns = index * 100_000_000
    entities: list[Entity] = []
    nodes: list[BeliefNode] = []
    edges: list[BeliefEdge] = []
    factors: list[Factor] = []
    nearest = 99.0
    for k in range(pedestrians):
        distance = round(1.2 + k * 1.7 + 0.8 * ((index * (k + 1)) % 50) / 50, 3)
        nearest = min(nearest, distance)
        eid = f"ped_{k + 1}"
        ref = EvidenceRef(topic=ref_topic, log_time_ns=t_ns, sequence=index)  # no reading logged
        entities.append(_synthetic_person(eid, k, distance, ref))
        risk = round(max(0.0, min(1.0, 1.4 / distance - 0.2)), 4)
        nodes += [
            BeliefNode(id=eid, kind="entity", label="pedestrian", p=0.91, entity=eid),
            BeliefNode(id=f"{eid}.distance", kind="state", p=0.95, value=distance, unit="m"),
            BeliefNode(id=f"{eid}.collision_risk", kind="state", p=0.9, value=risk),
        ]
        edges += [
            BeliefEdge(parent=eid, child=f"{eid}.distance", p=0.95, rule="lidar_range"),
            BeliefEdge(
                parent=f"{eid}.distance", child=f"{eid}.collision_risk", p=0.9, rule="ttc_model"
            ),
        ]
        factors.append(Factor(node=f"{eid}.distance", name="distance", value=distance, unit="m"))
    command = "STOP" if nearest < 2.0 else "SLOW"
    perception = Perception(
        entities=entities, sensors_used=["lidar", "camera"], sensors_unavailable=[]
    )
    belief = Belief(nodes=nodes, edges=edges)
    action = _synthetic_action(command, nearest, factors)
    return perception, belief, action, _synthetic_execution(index, command)


def _synthetic_person(eid: str, k: int, distance: float, ref: EvidenceRef) -> Entity:
    """The ``k``-th pedestrian of a synthetic cycle, seen by lidar and camera."""
    return Entity(
        id=eid,
        cls="person",
        pose=Pose(position=(distance, 0.3 * k, 0.0), orientation=(0.0, 0.0, 0.1, 0.995)),
        velocity=(0.1, -0.4, 0.0),
        confidence={"person": 0.91, "forklift": 0.04, "shelf": 0.05},
        evidence=[
            Evidence(
                sensor="lidar",
                weight=0.7,
                region=Region(kind="beams", values=[100.0 + k, 112.0 + k]),
                ref=ref,
            ),
            Evidence(
                sensor="camera",
                weight=0.3,
                region=Region(kind="pixels", values=[320.0, 200.0, 380.0, 420.0]),
                ref=ref.model_copy(update={"topic": "/sensors/camera"}),
            ),
        ],
    )


def _synthetic_action(command: str, nearest: float, factors: list[Factor]) -> Action:
    """The synthetic cycle's choice, with its alternatives, counterfactuals and tree."""
    return Action(
        command=command,
        parameters={"target_speed": 0.0 if command == "STOP" else 0.5},
        score=0.82,
        alternatives=[
            Alternative(command=c, score=s, rejected_because=r)
            for c, s, r in (
                ("SLOW", 0.41, "pedestrian inside the 2 m stop radius"),
                ("REROUTE", 0.22, "no free aisle within 10 m"),
                ("CONTINUE", 0.05, "collision risk above 0.2"),
            )
            if c != command
        ],
        rationale=Rationale(
            text=f"Pedestrian at {nearest:.2f} m; nearest entity governs the speed choice.",
            factors=factors,
        ),
        counterfactuals=[
            Counterfactual(
                factor="ped_1.distance", comparison=">=", threshold=2.0, would_select="SLOW"
            ),
            Counterfactual(
                factor="ped_1.collision_risk",
                comparison="<",
                threshold=0.2,
                would_select="CONTINUE",
            ),
        ],
        tree=_synthetic_tree(command),
    )


def _synthetic_tree(command: str) -> DecisionTree:
    return DecisionTree(
        nodes=[
            TreeNode(id="root", label="Decision point"),
            TreeNode(id="ped", label="pedestrian detected", test="d_ped < 2.0"),
            TreeNode(id="path", label="path clear?", test="aisle_blocked"),
            TreeNode(id="stop", label="STOP", command="STOP"),
            TreeNode(id="slow", label="SLOW", command="SLOW"),
            TreeNode(id="reroute", label="REROUTE", command="REROUTE"),
            TreeNode(id="continue", label="CONTINUE", command="CONTINUE"),
        ],
        edges=[
            TreeEdge(parent="root", child="ped", label="ped detected"),
            TreeEdge(parent="root", child="path", label="no ped"),
            TreeEdge(parent="ped", child="stop", label="yes"),
            TreeEdge(parent="ped", child="slow", label="no"),
            TreeEdge(parent="path", child="reroute", label="no"),
            TreeEdge(parent="path", child="continue", label="yes"),
        ],
        taken_path=["root", "ped", "stop" if command == "STOP" else "slow"],
    )


def _synthetic_execution(index: int, command: str) -> Execution:
    speed = 0.0 if command == "STOP" else 0.5
    return Execution(
        intended=Motion(linear=speed, angular=0.0),
        actual=Motion(linear=round(speed + 0.01 * (index % 7) / 7, 4), angular=0.0),
        deviation=round(0.01 * (index % 7) / 7, 4),
        checks=[
            ComplianceCheck(
                rule="speed_near_person",
                passed=True,
                value=speed,
                limit=0.5,
                detail="<= 0.5 m/s within 3 m of a person",
            )
        ],
        flags=[],
    )


def simulate_crash(logger: AuditLogger) -> None:
    """Leave a (synchronous) logger as a killed process would: every written batch stays on
    disk, the open segment never gets its summary or closing checkpoint, and the writer lock
    is gone (the kernel drops it with the process). For tests of crash recovery."""
    logger._chain.crash()
    logger._closed = True
