"""A ROS 2 robot's log root as a user's robot makes it, for the tests of evidence in recordings.

Two rosbag2 recordings (MCAP storage, metadata.yaml, CDR ``sensor_msgs/msg/LaserScan``)
written by ``rosbags``, not by this project, beside the log root; the robot logs with the
real ``AuditLogger`` on the wall clock and declares both recordings (``LoggerConfig
.recordings``). Every decision cites its front scan in ``front_bag``; every fifth also cites
a rear scan in ``rear_bag`` for a second factor; every tenth logs no alternatives (DR fails,
so metrics lists it). ``break_message`` and ``shutil.rmtree`` make the broken and the
missing-recording variants of a copy of the root.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter

from trace_runtime import (
    Action,
    Alternative,
    AuditLogger,
    Belief,
    BeliefEdge,
    BeliefNode,
    Counterfactual,
    Entity,
    Evidence,
    Execution,
    Factor,
    LoggerConfig,
    Motion,
    Perception,
    Pose,
    Rationale,
    Region,
    external_ref,
)

CYCLES = 30
PERIOD_NS = 100_000_000
T0_NS = 1_777_885_289_000_000_000
"""2026-05-04T09:01:29Z: a wall clock (``clock="system"``), as a ROS 2 robot's is."""
REAR_EVERY = 5
NO_ALTERNATIVES_EVERY = 10
ROBOT = "ward-bot"


def _scan(typestore: object, t_ns: int, distance: float) -> bytes:
    import numpy as np
    from rosbags.typesys.stores.ros2_humble import (
        builtin_interfaces__msg__Time as Time,
    )
    from rosbags.typesys.stores.ros2_humble import (
        sensor_msgs__msg__LaserScan as LaserScan,
    )
    from rosbags.typesys.stores.ros2_humble import (
        std_msgs__msg__Header as Header,
    )

    msg = LaserScan(
        header=Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="laser"),
        angle_min=-0.5,
        angle_max=0.5,
        angle_increment=0.25,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=12.0,
        ranges=np.array([8.0, distance, distance, 8.0, 8.0], dtype=np.float32),
        intensities=np.array([], dtype=np.float32),
    )
    data: bytes = bytes(typestore.serialize_cdr(msg, LaserScan.__msgtype__))  # type: ignore[attr-defined]
    return data


def write_root(site: Path, cycles: int = CYCLES) -> Path:
    """Write the robot's log root ``site/log`` and its recordings beside it,
    ``site/front_bag`` and ``site/rear_bag``; return the root."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    root, front, rear = site / "log", site / "front_bag", site / "rear_bag"
    config = LoggerConfig(fsync_interval_s=None, recordings=(front, rear))
    scan_type = "sensor_msgs/msg/LaserScan"
    with (
        Writer(front, version=9, storage_plugin=StoragePlugin.MCAP) as front_writer,
        Writer(rear, version=9, storage_plugin=StoragePlugin.MCAP) as rear_writer,
        AuditLogger(root, robot_id=ROBOT, period_s=PERIOD_NS / 1e9, config=config) as log,
    ):
        front_conn = front_writer.add_connection("/scan", scan_type, typestore=store)
        rear_conn = rear_writer.add_connection("/scan_rear", scan_type, typestore=store)
        for i in range(cycles):
            t_ns = T0_NS + i * PERIOD_NS
            distance = round(1.0 + 0.1 * i, 2)
            data = _scan(store, t_ns, distance)
            front_writer.write(front_conn, t_ns, data)
            refs = [("person_1", "person", external_ref(front, "/scan", t_ns, data))]
            if i % REAR_EVERY == 0:
                rear_data = _scan(store, t_ns, 5.0)
                rear_writer.write(rear_conn, t_ns, rear_data)
                refs.append(("cart_1", "cart", external_ref(rear, "/scan_rear", t_ns, rear_data)))
            with log.cycle(t_ns) as cycle:
                _decide(cycle, refs, distance, alternatives=i % NO_ALTERNATIVES_EVERY != 3)
    return root


def _decide(
    cycle: object, refs: list[tuple[str, str, object]], distance: float, *, alternatives: bool
) -> None:
    entities = [
        Entity(
            id=entity_id,
            cls=cls,
            pose=Pose(
                position=(distance if cls == "person" else -3.0, 0.5, 0.0), frame="base_link"
            ),
            confidence={cls: 0.9},
            evidence=[
                Evidence(
                    sensor="lidar",
                    weight=1.0,
                    region=Region(kind="beams", values=[1.0, 2.0]),
                    ref=ref,  # type: ignore[arg-type]
                )
            ],
        )
        for entity_id, cls, ref in refs
    ]
    nodes = [BeliefNode(id=e.id, kind="entity", p=0.9, entity=e.id) for e in entities]
    nodes.append(BeliefNode(id="person_1.distance", kind="state", p=0.95, value=distance, unit="m"))
    edges = [BeliefEdge(parent="person_1", child="person_1.distance", p=0.95, rule="range")]
    factors = [Factor(node="person_1.distance", name="distance", value=distance, unit="m")]
    if len(entities) > 1:
        factors.append(Factor(node="cart_1", name="cart", value=1.0))
    command = "STOP" if distance < 1.5 else "SLOW"
    cycle.perception(Perception(entities=entities, sensors_used=["lidar"]))  # type: ignore[attr-defined]
    cycle.belief(Belief(nodes=nodes, edges=edges))  # type: ignore[attr-defined]
    cycle.action(  # type: ignore[attr-defined]
        Action(
            command=command,
            alternatives=[Alternative(command="CONTINUE", score=0.1, rejected_because="person")]
            if alternatives
            else [],
            rationale=Rationale(text=f"person at {distance} m", factors=factors),
            counterfactuals=[
                Counterfactual(
                    factor="person_1.distance",
                    comparison=">=",
                    threshold=3.0,
                    would_select="CONTINUE",
                )
            ],
        )
    )
    cycle.execution(  # type: ignore[attr-defined]
        Execution(intended=Motion(linear=0.0), actual=Motion(linear=0.0), deviation=0.0)
    )


def copy_site(root: Path, dst: Path) -> Path:
    """A copy of a log root and the recordings beside it (moved together); the copy's root."""
    shutil.copytree(root.parent, dst)
    return dst / root.name


def break_message(bag: Path, t_ns: int) -> None:
    """Flip the last bytes of the message logged at ``t_ns`` in every MCAP file of ``bag``:
    the recording is there, but the message a ref cites no longer matches its digest."""
    for path in sorted(bag.glob("*.mcap")):
        with path.open("rb") as f_in:
            reader = make_reader(f_in)
            header = reader.get_header()
            items = [
                (schema, channel, message) for schema, channel, message in reader.iter_messages()
            ]
        with path.open("wb") as f_out:
            writer = McapWriter(f_out)
            writer.start(profile=header.profile, library=header.library)
            ids: dict[int, int] = {}
            for schema, channel, message in items:
                if channel.id not in ids:
                    assert schema is not None
                    sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                    ids[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding, sid
                    )
                data = message.data
                if message.log_time == t_ns:
                    data = data[:-4] + bytes(b ^ 0xFF for b in data[-4:])
                writer.add_message(
                    ids[channel.id], message.log_time, data, message.publish_time, message.sequence
                )
            writer.finish()
