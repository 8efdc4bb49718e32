"""What one robot's cycles show in Foxglove, in Foxglove's own schemas, for any sink (an
MCAP file, ``foxglove.export``; a live server, ``foxglove.live``): each cycle's scene update and
pose, its decision change, its factor and actuator numbers for the Plot panel, a warning
where cycles are missing (``FoxgloveView``); every channel the view may write
(``view_channels``) and the logger's schema of each TRACE channel copied beside them
(``logged_schema``). ``foxglove-sdk`` comes with the ``look`` extra (``require_sdk``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import orjson

from trace_audit.causal import Decision, layer_with_defaults, read_decision
from trace_audit.causal.lenient import as_float, as_mapping, as_str, mappings
from trace_audit.cycle_fields import command_of, is_decision_change, seal_dropped
from trace_audit.sensor_window import DEFAULT_SENSOR_WINDOW, SensorWindow
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import UsageError
from trace_runtime.gaps import GapFinder, SealedStamp
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_PERCEPTION
from trace_runtime.schemas import SENSOR_SCHEMA_NAME, schema_bytes, schema_name

__all__ = [
    "TOPIC_ACTUATORS",
    "TOPIC_DECISIONS",
    "TOPIC_FACTORS",
    "TOPIC_ROBOT_POSE",
    "TOPIC_SCENE",
    "FoxgloveMessage",
    "FoxgloveView",
    "logged_schema",
    "require_sdk",
    "view_channels",
]

TOPIC_SCENE = "/foxglove/scene"
TOPIC_ROBOT_POSE = "/foxglove/robot_pose"
TOPIC_DECISIONS = "/foxglove/decisions"
TOPIC_FACTORS = "/foxglove/factors"
TOPIC_ACTUATORS = "/foxglove/actuators"

_VERIFIED = (0.2, 0.75, 0.3, 0.9)
_UNVERIFIED = (0.95, 0.6, 0.1, 0.9)
"""Amber: evidence in a recording that could not be read (unknown, not failed)."""
_FAILED = (0.85, 0.2, 0.15, 0.9)
_ROBOT = (0.2, 0.45, 0.95, 0.9)
_ENTITY_SIZE_M = 0.5
_PLOT_KEY = re.compile(r"[^A-Za-z0-9_]")

_NUMBERS_SCHEMA: dict[str, Any] = {"type": "object", "additionalProperties": True}


def require_sdk() -> Any:
    """The ``foxglove`` package (the SDK); ``UsageError`` naming the extra when missing."""
    try:
        import foxglove
        import foxglove.channels
        import foxglove.messages
    except ImportError as err:
        raise UsageError(
            "the Foxglove export needs foxglove-sdk: pip install 'trace-audit[look]'"
        ) from err
    return foxglove


def _stamp(fox: Any, t_ns: int) -> Any:
    return fox.messages.Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


@dataclass(frozen=True, slots=True)
class FoxgloveMessage:
    """One message of the Foxglove view, ready for any sink: an MCAP file or a live server."""

    topic: str
    schema: tuple[str, str, bytes]
    """(name, encoding, data) of its schema: the SDK's protobuf descriptors, or a JSON Schema."""
    encoding: str
    """The message encoding: ``protobuf`` (the SDK's types) or ``json`` (the plot numbers)."""
    data: bytes
    t_ns: int


class FoxgloveView:
    """What one robot's cycles, in order, show in Foxglove: each cycle's scene update and
    pose, its decision change (if the command changed), its factors and actuator channels,
    as ``FoxgloveMessage`` values. It remembers the last command and a bounded window of
    sensor readings (what an entity's evidence refs are resolved against), so it can run
    over a whole export or a live tail alike."""

    def __init__(
        self, robot: str, period_ns: int = 0, recordings: Recordings | None = None
    ) -> None:
        self.fox = require_sdk()
        self.period_ns = period_ns
        """The cycle period gaps are found at (``trace_runtime.gaps``); 0: none shown."""
        self.gaps = GapFinder()
        self.m = self.fox.messages
        self.robot = robot
        # refs into external recordings resolve against the log's one resolution of them
        self.sensors = SensorWindow(DEFAULT_SENSOR_WINDOW, recordings)
        self.command: str | None = None
        self.cycles = self.scene_updates = self.entities = self.changes = 0
        self._last_xyz = (0.0, 0.0, 0.0)
        self._schemas: dict[type, tuple[str, str, bytes]] = {}

    def messages(self, cycle: Cycle) -> list[FoxgloveMessage]:
        """Everything one cycle contributes to the view, in order."""
        self.cycles += 1
        self.sensors.push(cycle.sensors)
        gap = self._gap(cycle)
        out = self._scene(cycle)
        if gap is not None:
            out.append(gap)
        decision = read_decision(cycle, with_tree=False)
        command = command_of(cycle)
        changed = is_decision_change(self.cycles > 1, self.command, command)
        self.changes += changed
        if self.cycles == 1 or changed:  # the first decision is shown, not counted
            out.append(self._decision(cycle, decision, command))
        self.command = command
        numbers = {
            _PLOT_KEY.sub("_", f.label): as_float(f.value)
            for f in decision.factors
            if as_float(f.value) is not None
        }
        out.append(_json(TOPIC_FACTORS, numbers, cycle.t_ns))
        execution = decision.execution
        if execution is not None:
            channels: dict[str, object] = {"deviation": execution.deviation}
            for channel in execution.channels:
                channels[_PLOT_KEY.sub("_", channel.name)] = {
                    "intended": channel.intended,
                    "actual": channel.actual,
                    "deviation": channel.deviation,
                }
            out.append(_json(TOPIC_ACTUATORS, channels, cycle.t_ns))
        return out

    def skip(self, cycle: Cycle) -> None:
        """Pass over a cycle no one is shown (a live view without a client): what the next
        cycles need is remembered (the command, the sensor window), nothing is built."""
        self.cycles += 1
        self.sensors.push(cycle.sensors)
        self._gap(cycle)
        self.command = command_of(cycle)

    def _schema(self, kind: type) -> tuple[str, str, bytes]:
        schema = self._schemas.get(kind)
        if schema is None:
            sdk = kind.get_schema()  # type: ignore[attr-defined]
            schema = self._schemas[kind] = (sdk.name, sdk.encoding, bytes(sdk.data))
        return schema

    def _sdk_message(self, topic: str, message: Any, t_ns: int) -> FoxgloveMessage:
        """A message of the SDK's own types, in its own schema and encoding (protobuf)."""
        schema = self._schema(type(message))
        return FoxgloveMessage(topic, schema, schema[1], bytes(message.encode()), t_ns)

    def _scene(self, cycle: Cycle) -> list[FoxgloveMessage]:
        m = self.m
        out: list[FoxgloveMessage] = []
        stamp = _stamp(self.fox, cycle.t_ns)
        perception = as_mapping(layer_with_defaults(cycle, TOPIC_PERCEPTION)) or {}
        entities = []
        robot_pose = as_mapping(perception.get("robot_pose"))
        if robot_pose is not None and (pose := self._pose(robot_pose)) is not None:
            frame = as_str(robot_pose.get("frame")) or ""
            entities.append(self._cube(stamp, frame, "robot", pose, colour=_ROBOT, label="robot"))
            out.append(
                self._sdk_message(
                    TOPIC_ROBOT_POSE,
                    m.PoseInFrame(timestamp=stamp, frame_id=frame, pose=pose),
                    cycle.t_ns,
                )
            )
        for entity in mappings(perception.get("entities")):
            shown = self._entity(stamp, entity)
            if shown is not None:
                entities.append(shown)
        self.entities += len(entities)
        everything = m.SceneEntityDeletion(timestamp=stamp, type=m.SceneEntityDeletionType.All)
        update = m.SceneUpdate(deletions=[everything], entities=entities)
        out.insert(0, self._sdk_message(TOPIC_SCENE, update, cycle.t_ns))
        self.scene_updates += 1
        return out

    def _entity(self, stamp: Any, entity: Mapping[str, Any]) -> Any:
        """A perceived entity as a cube and its label; None when it has no position."""
        pose_data = as_mapping(entity.get("pose"))
        pose = self._pose(pose_data) if pose_data is not None else None
        if pose is None or pose_data is None:
            return None
        cls = as_str(entity.get("class")) or "?"
        confidence = as_float((as_mapping(entity.get("confidence")) or {}).get(cls))
        refs = [as_mapping(e.get("ref")) for e in mappings(entity.get("evidence"))]
        problems = [self.sensors.resolve(dict(r)) if r is not None else "no ref" for r in refs]
        verified = bool(refs) and not any(problems)
        unknown = not verified and all(
            r is not None and (not why or self.sensors.unknown(dict(r)))
            for r, why in zip(refs, problems, strict=True)
        )
        label = f"{as_str(entity.get('id')) or '?'}: {cls}"
        if confidence is not None:
            label += f" {confidence:.2f}"
        if verified:
            label, colour = label + ", evidence verified", _VERIFIED
        elif unknown and refs:
            label, colour = label + ", evidence not checked (recording not read)", _UNVERIFIED
        else:
            label, colour = label + ", evidence FAILED", _FAILED
        frame = as_str(pose_data.get("frame")) or ""
        return self._cube(
            stamp, frame, as_str(entity.get("id")) or "", pose, colour=colour, label=label
        )

    def _pose(self, pose: Mapping[str, Any]) -> Any:
        """The SDK pose of a logged one; None without a finite x, y, z."""
        m = self.m
        position = pose.get("position")
        if not isinstance(position, list) or len(position) != 3:
            return None
        xyz = [as_float(v) for v in position]
        if any(v is None or not math.isfinite(v) for v in xyz):
            return None
        x, y, z = (float(v) for v in xyz if v is not None)
        self._last_xyz = (x, y, z)
        q = pose.get("orientation")
        quat = [as_float(v) for v in q] if isinstance(q, list) and len(q) == 4 else []
        if len(quat) != 4 or any(v is None for v in quat):
            quat = [0.0, 0.0, 0.0, 1.0]
        qx, qy, qz, qw = (float(v) for v in quat if v is not None)
        return m.Pose(
            position=m.Vector3(x=x, y=y, z=z), orientation=m.Quaternion(x=qx, y=qy, z=qz, w=qw)
        )

    def _cube(
        self,
        stamp: Any,
        frame: str,
        entity_id: str,
        pose: Any,
        *,
        colour: tuple[float, float, float, float],
        label: str,
    ) -> Any:
        m = self.m
        r, g, b, a = colour
        size = m.Vector3(x=_ENTITY_SIZE_M, y=_ENTITY_SIZE_M, z=_ENTITY_SIZE_M)
        x, y, z = self._last_xyz  # of ``pose``: the SDK's messages do not read back
        above = m.Pose(
            position=m.Vector3(x=x, y=y, z=z + _ENTITY_SIZE_M),
            orientation=m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        )
        return m.SceneEntity(
            timestamp=stamp,
            frame_id=frame,
            id=entity_id,
            cubes=[m.CubePrimitive(pose=pose, size=size, color=m.Color(r=r, g=g, b=b, a=a))],
            texts=[
                m.TextPrimitive(
                    pose=above,
                    billboard=True,
                    font_size=14.0,
                    scale_invariant=True,
                    color=m.Color(r=1.0, g=1.0, b=1.0, a=1.0),
                    text=label,
                )
            ],
        )

    def _gap(self, cycle: Cycle) -> FoxgloveMessage | None:
        """A warning in the Log panel when cycles are missing before this one (the one gap
        rule), so a decision change after it does not read as a direct one (as ``tail``)."""
        stamp = SealedStamp(cycle.cycle, cycle.t_ns, self.period_ns, seal_dropped(cycle))
        gap = self.gaps.step(self.robot, stamp)
        if gap is None:
            return None
        n = gap.missing_cycles
        text = (
            f"GAP after cycle {gap.after_cycle}: {n} cycle{'s' if n != 1 else ''} "
            f"({gap.gap_ns / 1e9:.3f} s) not logged"
        )
        return self._sdk_message(
            TOPIC_DECISIONS,
            self.m.Log(
                timestamp=_stamp(self.fox, cycle.t_ns),
                level=self.m.LogLevel.Warning,
                message=text,
                name=self.robot,
                file=cycle.segment,
                line=cycle.cycle,
            ),
            cycle.t_ns,
        )

    def _decision(self, cycle: Cycle, decision: Decision, command: str | None) -> FoxgloveMessage:
        m = self.m
        was = "" if self.cycles == 1 else f"{self.command} -> "
        text = f"cycle {cycle.cycle}: {was}{command}"
        if decision.leading is not None:
            text += f"; leading {decision.leading.label} = {decision.leading.shown}"
        if decision.rationale:
            text += f"; because {decision.rationale}"
        return self._sdk_message(
            TOPIC_DECISIONS,
            m.Log(
                timestamp=_stamp(self.fox, cycle.t_ns),
                level=m.LogLevel.Info,
                message=text,
                name=self.robot,  # the robot's id (it may hold "_", as a segment name does)
                file=cycle.segment,
                line=cycle.cycle,
            ),
            cycle.t_ns,
        )


def view_channels() -> list[tuple[str, tuple[str, str, bytes], str]]:
    """Every channel the view may write: (topic, schema, message encoding), so a live sink
    can advertise them all before the first message."""
    m = require_sdk().messages
    typed = [
        (TOPIC_SCENE, m.SceneUpdate),
        (TOPIC_ROBOT_POSE, m.PoseInFrame),
        (TOPIC_DECISIONS, m.Log),
    ]
    found = []
    for topic, kind in typed:
        sdk = kind.get_schema()
        found.append((topic, (sdk.name, sdk.encoding, bytes(sdk.data)), "protobuf"))
    for topic in (TOPIC_FACTORS, TOPIC_ACTUATORS):
        found.append((topic, _json_schema(topic), "json"))
    return found


def _json_schema(topic: str) -> tuple[str, str, bytes]:
    return topic.rsplit("/", 1)[-1], "jsonschema", orjson.dumps(_NUMBERS_SCHEMA)


def _json(topic: str, value: Mapping[str, object], t_ns: int) -> FoxgloveMessage:
    return FoxgloveMessage(topic, _json_schema(topic), "json", orjson.dumps(value), t_ns)


def logged_schema(topic: str) -> tuple[str, str, bytes]:
    """The schema the logger gives a topic (``trace_runtime.schemas``): the export's TRACE
    channels are the hot tier's, whatever tier the log was read from."""
    name = schema_name(topic) if topic.startswith("/trace/") else SENSOR_SCHEMA_NAME
    return name, "jsonschema", schema_bytes(topic)
