"""A hospital robot's rosbag2 recording and the TRACE log that cites it, made from outside.

The recording is written by ``rosbags`` (not this project's writer) as ``ros2 bag record``
writes one: a bag folder with ``metadata.yaml`` and an MCAP file of CDR messages with their
``ros2msg`` schemas: ``sensor_msgs/msg/LaserScan`` on ``/scan``,
``vision_msgs/msg/Detection2DArray`` on ``/detections`` (its types registered from their
``.msg`` text, as vision_msgs 4 defines them) and ``sensor_msgs/msg/JointState`` on
``/joint_states``. The log is written by the real ``AuditLogger`` on a wall clock, at 20 Hz,
citing those messages through ``external_ref``: the person's evidence names the scan beams
and the camera box it came from, the arm's channel the joint state its actual value was read
from. The robot says its wrist camera is unavailable, and from cycle ``STALE_FROM`` on it
keeps citing the same old scan (a stuck driver).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trace_runtime import (
    Action,
    ActuatorChannel,
    AuditLogger,
    Belief,
    BeliefEdge,
    BeliefNode,
    Entity,
    Evidence,
    Execution,
    Factor,
    LoggerConfig,
    Perception,
    Pose,
    Rationale,
    Region,
    external_ref,
)

START_NS = 1_777_885_289_838_000_000
"""2026-05-04T09:01:29.838Z: a wall clock."""
PERIOD_NS = 50_000_000
CYCLES = 12
STALE_FROM = 8
BEAMS = 181
NEAR_BEAMS = (80, 84)
NEAR_M = 1.25
CAMERA_BOX = (280.0, 140.0, 360.0, 340.0)

_VISION = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox2D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection2DArray": (
        "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n"
    ),
}


@dataclass(frozen=True)
class Robot:
    log: Path
    bag: Path


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in _VISION.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def _messages(store: Any, t_ns: int) -> dict[str, tuple[str, Any]]:
    """The three messages recorded at ``t_ns``, by topic: (type, message)."""
    m = store.types
    header = m["std_msgs/msg/Header"](
        stamp=m["builtin_interfaces/msg/Time"](
            sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000
        ),
        frame_id="base_laser",
    )
    ranges = np.full(BEAMS, 6.0, dtype=np.float32)
    ranges[NEAR_BEAMS[0] : NEAR_BEAMS[1] + 1] = NEAR_M
    ranges[0] = np.inf  # no return on the first beam
    scan = m["sensor_msgs/msg/LaserScan"](
        header=header, angle_min=-1.5708, angle_max=1.5708, angle_increment=3.1416 / 180,
        time_increment=0.0, scan_time=0.05, range_min=0.1, range_max=12.0, ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )  # fmt: skip
    x0, y0, x1, y1 = CAMERA_BOX
    pose = m["geometry_msgs/msg/PoseWithCovariance"](
        pose=m["geometry_msgs/msg/Pose"](
            position=m["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
            orientation=m["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        ),
        covariance=np.zeros(36),
    )
    detection = m["vision_msgs/msg/Detection2D"](
        header=header,
        results=[
            m["vision_msgs/msg/ObjectHypothesisWithPose"](
                hypothesis=m["vision_msgs/msg/ObjectHypothesis"](class_id="person", score=0.91),
                pose=pose,
            )
        ],
        bbox=m["vision_msgs/msg/BoundingBox2D"](
            center=m["vision_msgs/msg/Pose2D"](
                position=m["vision_msgs/msg/Point2D"](x=(x0 + x1) / 2, y=(y0 + y1) / 2),
                theta=0.0,
            ),
            size_x=x1 - x0,
            size_y=y1 - y0,
        ),
        id="track_7",
    )
    detections = m["vision_msgs/msg/Detection2DArray"](header=header, detections=[detection])
    joints = m["sensor_msgs/msg/JointState"](
        header=header,
        name=["shoulder", "elbow"],
        position=np.array([0.1, 0.52]),
        velocity=np.array([0.0, 0.48]),
        effort=np.array([1.0, 2.0]),
    )
    return {
        "/scan": ("sensor_msgs/msg/LaserScan", scan),
        "/detections": ("vision_msgs/msg/Detection2DArray", detections),
        "/joint_states": ("sensor_msgs/msg/JointState", joints),
    }


def record(bag: Path) -> dict[tuple[str, int], bytes]:
    """Write the recording; the CDR bytes of every message by (topic, log time)."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = _typestore()
    stored: dict[tuple[str, int], bytes] = {}
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections: dict[str, Any] = {}
        for i in range(CYCLES):
            t_ns = START_NS + i * PERIOD_NS - 10_000_000  # 10 ms before the decision
            for topic, (kind, message) in _messages(store, t_ns).items():
                if topic not in connections:
                    connections[topic] = writer.add_connection(topic, kind, typestore=store)
                data = bytes(store.serialize_cdr(message, kind))
                writer.write(connections[topic], t_ns, data)
                stored[topic, t_ns] = data
    return stored


def write_robot(folder: Path) -> Robot:
    """The recording, then the log citing it (the bag declared, found without a flag)."""
    bag = folder / "ward_bag"
    stored = record(bag)
    log = folder / "ward.mcap"
    config = LoggerConfig(fsync_interval_s=None, recordings=(bag,))
    with AuditLogger(log, robot_id="ward-bot", period_s=PERIOD_NS / 1e9, config=config) as logger:
        for i in range(CYCLES):
            t_ns = START_NS + i * PERIOD_NS
            scan_t = START_NS + min(i, STALE_FROM) * PERIOD_NS - 10_000_000
            at = t_ns - 10_000_000

            def ref(topic: str, when: int) -> Any:
                return external_ref(bag, topic, when, stored[topic, when])

            with logger.cycle(t_ns) as cycle:
                _decide(cycle, ref("/scan", scan_t), ref("/detections", at))
                cycle.execution(
                    Execution(
                        deviation=0.04,
                        channels=[
                            ActuatorChannel(
                                name="elbow", unit="rad/s", intended=0.52, actual=0.48,
                                deviation=0.04, ref=ref("/joint_states", at),
                            )
                        ],
                    )
                )  # fmt: skip
    return Robot(log, bag)


def _decide(cycle: Any, scan: Any, camera: Any) -> None:
    cycle.perception(
        Perception(
            entities=[
                Entity(
                    id="person_1",
                    cls="person",
                    pose=Pose(position=(NEAR_M, 0.0, 0.0), frame="base_link"),
                    confidence={"person": 0.91},
                    evidence=[
                        Evidence(
                            sensor="lidar",
                            weight=0.6,
                            region=Region(kind="beams", values=[float(b) for b in NEAR_BEAMS]),
                            ref=scan,
                        ),
                        Evidence(
                            sensor="head_camera",
                            weight=0.4,
                            region=Region(kind="pixels", values=list(CAMERA_BOX)),
                            ref=camera,
                        ),
                    ],
                )
            ],
            sensors_used=["lidar", "head_camera"],
            sensors_unavailable=["wrist_camera"],
        )
    )
    cycle.belief(
        Belief(
            nodes=[
                BeliefNode(id="person_1", kind="entity", p=0.91, entity="person_1"),
                BeliefNode(id="person_distance", kind="state", p=0.9, value=NEAR_M, unit="m"),
            ],
            edges=[BeliefEdge(parent="person_1", child="person_distance", p=0.9, rule="range")],
        )
    )
    cycle.action(
        Action(
            command="STOP",
            rationale=Rationale(
                text="a person steps out of a door",
                factors=[Factor(node="person_distance", name="distance", value=NEAR_M, unit="m")],
            ),
            counterfactuals_none_applicable=True,
        )
    )
