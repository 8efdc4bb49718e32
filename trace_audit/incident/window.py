"""What the report's figures read from the window's cycles, beyond the library's answers:
each cycle as a ``Sample`` (command, factor values, execution channels), and the scene at t
(the perceived entities, each evidence ref resolved as the chain walker resolves it, and
the robot's pose). ``execution_channels`` is the one reader of an execution record's shapes
for every figure and table of the report."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from trace_audit.causal import ExecutionView, format_value, layer_with_defaults, read_decision
from trace_audit.causal.lenient import as_float, mappings
from trace_audit.chains import DEFAULT_SENSOR_WINDOW, SensorWindow
from trace_audit.explanation import Explanation
from trace_audit.log_time import SECONDS_CLOCK, LogClock
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.logset import Log
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_BELIEF, TOPIC_PERCEPTION

__all__ = [
    "EntityView",
    "EvidenceState",
    "EvidenceView",
    "RobotPose",
    "Sample",
    "entities_at",
    "execution_channels",
    "robot_pose",
    "window_samples",
]


def execution_channels(view: ExecutionView) -> dict[str, tuple[float | None, float | None]]:
    """Each execution channel the record offers: name (with unit) -> (intended, actual).

    The one place that knows the shapes of the execution record: the planar motion of a
    mobile base, and the named actuator channels (joints, a gripper, thrust) of profile 1.1
    in the robot's own names and units. Every figure and table of the report follows it."""
    shown: dict[str, tuple[float | None, float | None]] = {}
    if view.planar:
        shown["linear speed (m/s)"] = (view.intended[0], view.actual[0])
        shown["angular speed (rad/s)"] = (view.intended[1], view.actual[1])
    for channel in view.channels:
        shown[f"{channel.name} ({channel.unit})"] = (channel.intended, channel.actual)
    return shown


@dataclass(frozen=True, slots=True)
class Sample:
    """One cycle of the window, as the factor and execution figures plot it."""

    cycle: int
    t_ns: int
    command: str | None
    factors: dict[str, float]
    """Factor name -> numeric value, for the factors this cycle's action names."""
    factor_nodes: dict[str, str]
    """Factor name -> the belief node it was read from (``ped_2.distance``): whose value it is."""
    scenario: str | None
    channels: dict[str, tuple[float | None, float | None]]
    deviation: float | None
    failed_checks: tuple[str, ...]


EvidenceState = Literal["resolved", "broken", "unresolved"]
"""What became of an evidence item's ref: it resolves; it does not (no ref, no reading, a
changed reading: a finding); or it lies in an external recording that could not be read
(unknown, not a finding)."""


@dataclass(frozen=True, slots=True)
class EvidenceView:
    """One item of an entity's evidence, and whether its ref resolves to a logged reading."""

    sensor: str
    weight: float | None
    region: str
    ref: str
    state: EvidenceState
    problem: str

    @property
    def resolved(self) -> bool:
        return self.state == "resolved"


@dataclass(frozen=True, slots=True)
class EntityView:
    """A perceived entity at t: where, what, how sure, on which evidence."""

    id: str
    cls: str
    confidence: float | None
    x: float | None
    y: float | None
    frame: str
    evidence: tuple[EvidenceView, ...]
    distance: str | None
    """The belief graph's distance to it, as logged (``<id>.distance``), when there is one."""

    @property
    def evidence_state(self) -> EvidenceState:
        """resolved when any evidence item resolves; else unresolved when one lies in a
        recording that could not be read (unknown); else broken (none, or none resolves)."""
        states = {e.state for e in self.evidence}
        if "resolved" in states:
            return "resolved"
        return "unresolved" if "unresolved" in states else "broken"

    @property
    def evidence_failed(self) -> bool:
        """No evidence at all, or none of it resolves, and none is merely unknown."""
        return self.evidence_state == "broken"


@dataclass(frozen=True, slots=True)
class RobotPose:
    """Where the robot was at t, as its perception record says (``robot_pose``)."""

    x: float
    y: float
    heading_rad: float
    frame: str


def window_samples(
    log: Log, start_ns: int, end_ns: int, result: Explanation, recordings: Recordings | None
) -> tuple[tuple[Sample, ...], Cycle | None, SensorWindow]:
    """The window's cycles as samples, the decision's own cycle (for the scene) and the
    sensor readings in reach of its evidence refs.

    Sensor readings are pushed through a ``SensorWindow`` of the explain default, over the
    report's one resolution of external ``recordings``, so the scene's evidence resolves
    exactly as the chain walker resolves it."""
    names = {f.label for f in result.decision.factors}
    period = max(result.period_ns, 1)
    lead_ns = (DEFAULT_SENSOR_WINDOW + 1) * period
    window = SensorWindow(DEFAULT_SENSOR_WINDOW, recordings)
    samples: list[Sample] = []
    target: Cycle | None = None
    for c in log.iter_cycles(min(start_ns, result.t_ns - lead_ns), max(end_ns, result.t_ns)):
        if c.t_ns <= result.t_ns:
            window.push(c.sensors)
        if c.cycle == result.cycle and c.t_ns == result.t_ns:
            target = c
        if c.t_ns < start_ns or c.t_ns > end_ns:
            continue
        d = read_decision(c)
        ex = d.execution
        samples.append(
            Sample(
                cycle=c.cycle,
                t_ns=c.t_ns,
                command=d.command,
                factors={
                    f.label: value
                    for f in d.factors
                    if f.label in names and (value := as_float(f.value)) is not None
                },
                factor_nodes={f.label: f.node for f in d.factors if f.label in names},
                scenario=ex.scenario if ex is not None else None,
                channels=execution_channels(ex) if ex is not None else {},
                deviation=ex.deviation if ex is not None else None,
                failed_checks=tuple(ch.rule for ch in ex.checks if not ch.passed)
                if ex is not None
                else (),
            )
        )
    return tuple(samples), target, window


def entities_at(
    target: Cycle, sensors: SensorWindow, clock: LogClock = SECONDS_CLOCK
) -> tuple[EntityView, ...]:
    """The perceived entities of the decision's cycle, each evidence ref resolved (its time
    shown in the log's ``clock``)."""
    perception = layer_with_defaults(target, TOPIC_PERCEPTION)
    belief = target.layer(TOPIC_BELIEF)
    distances: dict[str, str] = {}
    if isinstance(belief, Mapping):
        for node in mappings(belief.get("nodes")):
            node_id = node.get("id")
            if isinstance(node_id, str) and node_id.endswith(".distance"):
                unit = node.get("unit")
                distances[node_id[: -len(".distance")]] = format_value(
                    node.get("value"), unit if isinstance(unit, str) else None
                )
    if not isinstance(perception, Mapping):
        return ()
    out = []
    for raw in mappings(perception.get("entities")):
        entity_id = str(raw.get("id", "?"))
        cls = str(raw.get("class", "?"))
        pose = raw.get("pose") if isinstance(raw.get("pose"), Mapping) else {}
        position = pose.get("position") if isinstance(pose, Mapping) else None
        xy = _xy(position)
        confidence = raw.get("confidence")
        p = confidence.get(cls) if isinstance(confidence, Mapping) else None
        out.append(
            EntityView(
                id=entity_id,
                cls=cls,
                confidence=as_float(p),
                x=xy[0],
                y=xy[1],
                frame=str(pose.get("frame", "map")) if isinstance(pose, Mapping) else "map",
                evidence=tuple(_evidence(e, sensors, clock) for e in mappings(raw.get("evidence"))),
                distance=distances.get(entity_id),
            )
        )
    return tuple(out)


def robot_pose(target: Cycle) -> RobotPose | None:
    """The robot's own pose from the perception record, when the robot logged one."""
    perception = target.layer(TOPIC_PERCEPTION)
    pose = perception.get("robot_pose") if isinstance(perception, Mapping) else None
    if not isinstance(pose, Mapping):
        return None
    x, y = _xy(pose.get("position"))
    if x is None or y is None:
        return None
    q = pose.get("orientation")
    heading = 0.0
    if isinstance(q, list | tuple) and len(q) == 4 and all(as_float(v) is not None for v in q):
        qx, qy, qz, qw = (float(v) for v in q)
        # yaw of a unit quaternion (x, y, z, w)
        heading = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return RobotPose(x, y, heading, str(pose.get("frame", "map")))


def _evidence(raw: Mapping[str, object], sensors: SensorWindow, clock: LogClock) -> EvidenceView:
    ref = raw.get("ref")
    region = raw.get("region")
    where = ""
    if isinstance(region, Mapping):
        values = ", ".join(
            f"{v:g}" if as_float(v) is not None else str(v) for v in region.get("values") or ()
        )
        where = f"{region.get('kind')} [{values}] in {region.get('frame', '?')}"
    weight = raw.get("weight")
    state: EvidenceState = "broken"
    if isinstance(ref, dict):
        problem = sensors.resolve(ref)
        recording = ref.get("recording")
        stamp = ref.get("log_time_ns")
        when = clock.show(stamp) if type(stamp) is int else "?"
        label = (
            f"{recording} " if isinstance(recording, str) else ""
        ) + f"{ref.get('topic')} @ {when}"
        if not problem:
            state = "resolved"
        elif sensors.unknown(ref):
            state = "unresolved"
    else:
        problem, label = "no evidence ref recorded", "-"
    return EvidenceView(
        sensor=str(raw.get("sensor", "?")),
        weight=as_float(weight),
        region=where,
        ref=label,
        state=state,
        problem=problem,
    )


def _xy(position: object) -> tuple[float | None, float | None]:
    if isinstance(position, list | tuple) and len(position) >= 2:
        x, y = as_float(position[0]), as_float(position[1])
        if x is not None and y is not None:
            return x, y
    return None, None
