"""A ROS 2 robot: rosbag2 records its sensors in another process, its TRACE log cites them.

    trace-audit keygen --out keys/ --name ros2-bot        # the robot's checkpoint key
    python examples/ros2_robot.py --out robot_log --key keys/ros2-bot.key
    trace-audit explain robot_log --t 2.0     # the cited scan: resolved, checked, decoded
    trace-audit verify robot_log --key keys/ros2-bot.pub   # every cited scan checked too
    trace-audit doctor robot_log
    trace-audit metrics robot_log
    trace-audit timeline robot_log
    trace-audit why robot_log --action STOP
    trace-audit report robot_log --t 2.0 --out incident.html
    trace-audit export robot_log --t 2.0 --format dot
    trace-audit index robot_log --out robot_index
    trace-audit prove robot_log --cycle 10 --out proof.json
    trace-audit verify-proof proof.json --key keys/ros2-bot.pub

The bag goes to ``robot_log_bag/`` beside the root (``--bag`` to choose); without ``--key``
the checkpoints are unsigned and ``prove`` has nothing to prove against.

A ROS 2 robot already records its sensors with ``ros2 bag record``, in a process of its own,
into a bag folder of split MCAP files (``<bag>_0.mcap``, ``<bag>_1.mcap``, ... and
``metadata.yaml``). Copying every scan into the TRACE log as well would store it twice;
instead the robot declares the bag (``LoggerConfig(recordings=(bag,))``: every command then
finds it without ``--evidence``) and each evidence ref names a message in it by what it is:
the recording (the bag folder's name, never a file name: the robot cannot know which split a
message lands in), topic, log time and the SHA-256 of its CDR bytes (PROFILE.md section 11).

No ``sequence`` is passed: rosbag2 writes sequence 0 for every message, so a ref carrying a
count of its own would not match. Pass ``sequence`` only when the recorder numbers messages.

The recorder here stands in for ``ros2 bag record --use-sim-time -d 2 /scan /joint_states``:
a separate process (this file run with ``--record``) that receives each published message's
CDR bytes and writes them with the ``rosbags`` library as rosbag2 does, a split every 2 s.
The robot runs in simulated time (``clock="sim"``): the recorder's receive time, its log
time, is then the simulation tick the message was published at, which the robot knows. The
robot cites its ``/scan`` (``sensor_msgs/msg/LaserScan``); ``/joint_states`` at 50 Hz is
recorded and cited by nothing. On a ROS 2 robot the bytes to digest are the serialized
message rclpy received (``rclpy.serialization.serialize_message``).
"""

from __future__ import annotations

import argparse
import copy
import math
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, BinaryIO

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

TOPICS = {"/scan": "sensor_msgs/msg/LaserScan", "/joint_states": "sensor_msgs/msg/JointState"}
"""What the recorder subscribes to, as ``ros2 bag record /scan /joint_states`` would."""
JOINT_STATES_PER_CYCLE = 5  # 50 Hz beside a 10 Hz decision loop
BEAMS = 32
FIELD_OF_VIEW_RAD = math.pi / 2
STOP_BELOW_M = 1.5
SLOW_BELOW_M = 3.0
SPEEDS = {"STOP": 0.0, "SLOW": 0.3, "CONTINUE": 0.8}
_FRAME = struct.Struct("<HqI")  # one published message: topic length, log time, data length


SEAL_WAIT_S = 2.5
"""How long the robot's loop runs on after its recorder stopped: the logger's default
sealing lag (1 s window, 1 s settle, 0.5 s poll), so the bag's last messages are sealed."""


def choose(distance_m: float) -> str:
    """The robot's policy: stop near an obstacle, slow down when one is close, else go on."""
    if distance_m < STOP_BELOW_M:
        return "STOP"
    if distance_m < SLOW_BELOW_M:
        return "SLOW"
    return "CONTINUE"


# --- the sensors: ROS 2 messages as CDR bytes --------------------------------------------


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _header(types: Any, t_ns: int, frame: str) -> Any:
    stamp = types.types["builtin_interfaces/msg/Time"](
        sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000
    )
    return types.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def scan_ranges(i: int) -> list[float]:
    """A LaserScan's ranges in which a pallet ahead comes closer and recedes again."""
    obstacle = 0.8 + 4.0 * abs(math.sin(i / 20))
    return [
        round(obstacle if BEAMS // 2 - 3 <= beam <= BEAMS // 2 + 3 else 8.0 + 0.01 * beam, 3)
        for beam in range(BEAMS)
    ]


def scan_cdr(types: Any, t_ns: int, ranges: list[float]) -> bytes:
    """The scan as the lidar driver publishes it, serialized as rosbag2 stores it (CDR)."""
    import numpy as np

    scan = types.types["sensor_msgs/msg/LaserScan"](
        header=_header(types, t_ns, "base_laser"),
        angle_min=-FIELD_OF_VIEW_RAD / 2,
        angle_max=FIELD_OF_VIEW_RAD / 2,
        angle_increment=FIELD_OF_VIEW_RAD / (BEAMS - 1),
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.1,
        range_max=12.0,
        ranges=np.array(ranges, dtype=np.float32),
        intensities=np.array([], dtype=np.float32),
    )
    return bytes(types.serialize_cdr(scan, TOPICS["/scan"]))


def joint_states_cdr(types: Any, t_ns: int, speed: float) -> bytes:
    """The wheel joints' state (recorded, cited by no decision)."""
    import numpy as np

    wheel = speed / 0.1  # rad/s of a 0.1 m wheel
    state = types.types["sensor_msgs/msg/JointState"](
        header=_header(types, t_ns, "base_link"),
        name=["wheel_left", "wheel_right"],
        position=np.array([wheel * t_ns / 1e9] * 2, dtype=np.float64),
        velocity=np.array([wheel, wheel], dtype=np.float64),
        effort=np.array([], dtype=np.float64),
    )
    return bytes(types.serialize_cdr(state, TOPICS["/joint_states"]))


# --- the recorder: what `ros2 bag record` does, in its own process ------------------------


def record(bag: Path, split_s: float, stream: BinaryIO) -> int:
    """Record every message published on ``stream`` into the rosbag2 folder ``bag``, a split
    file every ``split_s`` seconds of log time (``ros2 bag record -d``); return the count.

    rosbags' Writer writes one MCAP file per bag, named after its folder; so each split is
    written by a Writer of its own in a staging folder named ``<bag>_<n>``, whose file
    ``<bag>_<n>.mcap`` is moved into the bag when the split closes (``.recording/`` holds
    the split being written), and ``metadata.yaml``
    lists the splits so far, as rosbag2 rewrites it at each split."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    types = _typestore()
    bag.mkdir(parents=True)
    splits: list[dict[str, Any]] = []
    writer: Any = None
    split_end = count = 0
    while header := stream.read(_FRAME.size):
        size, t_ns, length = _FRAME.unpack(header)
        topic, data = stream.read(size).decode(), stream.read(length)
        if writer is None or t_ns >= split_end:
            if writer is not None:
                splits.append(_close_split(writer, bag, splits))
            staging = bag / ".recording" / f"{bag.name}_{len(splits)}"
            writer = Writer(staging, version=9, storage_plugin=StoragePlugin.MCAP)
            writer.open()
            conns = {
                t: writer.add_connection(t, kind, typestore=types) for t, kind in TOPICS.items()
            }
            split_end = t_ns + round(split_s * 1e9)
        writer.write(conns[topic], t_ns, data)
        count += 1
    if writer is not None:
        splits.append(_close_split(writer, bag, splits))
    return count


def _close_split(writer: Any, bag: Path, done: list[dict[str, Any]]) -> dict[str, Any]:
    """Finish one split: its file into the bag, the bag's metadata.yaml listing every split
    so far; return the split's own metadata."""
    from ruamel.yaml import YAML

    writer.close()
    staging: Path = writer.path
    name = f"{staging.name}.mcap"
    (staging / name).replace(bag / name)
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False  # as rosbag2 and rosbags write it
    info = yaml.load((staging / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    shutil.rmtree(staging.parent)
    with (bag / "metadata.yaml").open("w") as out:
        yaml.dump({"rosbag2_bagfile_information": bag_metadata([*done, info])}, out)
    return info


def bag_metadata(splits: list[dict[str, Any]]) -> dict[str, Any]:
    """A bag's ``rosbag2_bagfile_information`` from its splits' own: every file, the
    message counts summed, the time range of them all."""
    whole = copy.deepcopy(splits[-1])
    whole["relative_file_paths"] = [s["relative_file_paths"][0] for s in splits]
    whole["files"] = [s["files"][0] for s in splits]
    whole["message_count"] = sum(s["message_count"] for s in splits)
    start = min(f["starting_time"]["nanoseconds_since_epoch"] for f in whole["files"])
    end = max(
        f["starting_time"]["nanoseconds_since_epoch"] + f["duration"]["nanoseconds"]
        for f in whole["files"]
    )
    whole["starting_time"] = {"nanoseconds_since_epoch": start}
    whole["duration"] = {"nanoseconds": end - start}
    counts: dict[str, int] = {}
    for split in splits:
        for topic in split["topics_with_message_count"]:
            name = topic["topic_metadata"]["name"]
            counts[name] = counts.get(name, 0) + topic["message_count"]
    for topic in whole["topics_with_message_count"]:
        topic["message_count"] = counts[topic["topic_metadata"]["name"]]
    return whole


# --- the robot: decisions logged with AuditLogger, citing the bag -------------------------


def decide(cycle: Any, distance: float, ref: Any, beams: tuple[int, int]) -> str:
    """Hand the perception, belief and action of one decision to the logger; return the
    command."""
    cycle.perception(
        Perception(
            entities=[
                Entity(
                    id="obstacle_1",
                    cls="pallet",
                    pose=Pose(position=(distance, 0.0, 0.0), frame="base_link"),
                    confidence={"pallet": 0.85, "person": 0.15},
                    evidence=[
                        Evidence(
                            sensor="lidar",
                            weight=1.0,
                            region=Region(kind="beams", values=[float(beams[0]), float(beams[1])]),
                            ref=ref,
                        )
                    ],
                )
            ],
            sensors_used=["lidar"],
        )
    )
    risk = round(min(1.0, 1.2 / distance), 3)
    cycle.belief(
        Belief(
            nodes=[
                BeliefNode(id="obstacle_1", kind="entity", p=0.85, entity="obstacle_1"),
                BeliefNode(id="obstacle_distance", kind="state", p=0.95, value=distance, unit="m"),
                BeliefNode(id="collision_risk", kind="state", p=risk, value=risk),
            ],
            edges=[
                BeliefEdge(parent="obstacle_1", child="obstacle_distance", p=0.95, rule="range"),
                BeliefEdge(parent="obstacle_distance", child="collision_risk", p=0.9, rule="ttc"),
            ],
        )
    )
    command = choose(distance)
    cycle.action(_action(command, distance))
    return command


def _action(command: str, distance: float) -> Action:
    return Action(
        command=command,
        alternatives=[
            Alternative(command=c, score=0.1, rejected_because=f"{distance:.2f} m ahead")
            for c in SPEEDS
            if c != command
        ],
        rationale=Rationale(
            text=f"obstacle at {distance:.2f} m",
            factors=[Factor(node="obstacle_distance", name="distance", value=distance, unit="m")],
        ),
        counterfactuals=[
            Counterfactual(
                factor="obstacle_distance",
                comparison="<" if command != "STOP" else ">=",
                threshold=STOP_BELOW_M,
                would_select="STOP" if command != "STOP" else "SLOW",
            )
        ],
    )


def _publish(recorder: BinaryIO, topic: str, t_ns: int, data: bytes) -> None:
    """Publish a message: the recorder process receives it (DDS, on a real robot)."""
    recorder.write(_FRAME.pack(len(topic), t_ns, len(data)) + topic.encode() + data)


def run(
    out: str, bag: str | None, cycles: int, period_s: float, key: str | None = None
) -> tuple[Path, Path]:
    """Drive ``cycles`` decisions while a recorder process records the sensors; return
    (log root, bag folder)."""
    root = Path(out)
    bag_dir = Path(bag) if bag else root.with_name(root.name + "_bag")
    if bag_dir.exists():  # `ros2 bag record -o` refuses an existing bag too
        raise SystemExit(f"{bag_dir} exists: give another --bag or remove it")
    types = _typestore()
    recorder = subprocess.Popen(
        [sys.executable, __file__, "--record", str(bag_dir)], stdin=subprocess.PIPE
    )
    assert recorder.stdin is not None
    config = LoggerConfig(fsync_interval_s=None, recordings=(bag_dir,), checkpoint_key=key)
    speed, beams = SPEEDS["CONTINUE"], (BEAMS // 2 - 3, BEAMS // 2 + 3)
    period_ns = round(period_s * 1e9)
    with AuditLogger(
        root, robot_id="ros2-bot", period_s=period_s, clock="sim", config=config
    ) as log:
        for i in range(cycles):
            t_ns = 1_000_000_000 + i * period_ns  # the simulation's /clock
            for k in range(JOINT_STATES_PER_CYCLE):
                at = t_ns + k * period_ns // JOINT_STATES_PER_CYCLE
                _publish(recorder.stdin, "/joint_states", at, joint_states_cdr(types, at, speed))
            ranges = scan_ranges(i)
            data = scan_cdr(types, t_ns, ranges)
            _publish(recorder.stdin, "/scan", t_ns, data)
            ref = external_ref(bag_dir, "/scan", t_ns, data)  # the bag by name; no sequence
            distance = min(ranges[beams[0] : beams[1] + 1])
            with log.cycle(t_ns) as cycle:
                target = SPEEDS[decide(cycle, distance, ref, beams)]
                speed += 0.6 * (target - speed)
                cycle.execution(
                    Execution(
                        intended=Motion(linear=target),
                        actual=Motion(linear=round(speed, 3)),
                        deviation=round(abs(target - speed), 3),
                    )
                )
        recorder.stdin.close()  # the recorder is stopped first: it ends its last split
        if recorder.wait(timeout=60) != 0:
            raise SystemExit(f"the recorder failed (exit {recorder.returncode})")
        # The robot's loop goes on a moment, on its last scan, while its logger seals what
        # the recorder wrote last: recorded messages are sealed into the cycles logged after
        # they land, so what is recorded after the robot's last cycle stays unsealed.
        for _ in range(round(SEAL_WAIT_S / period_s)):
            t_ns += period_ns
            with log.cycle(t_ns) as cycle:
                target = SPEEDS[decide(cycle, distance, ref, beams)]
                speed += 0.6 * (target - speed)
                cycle.execution(
                    Execution(
                        intended=Motion(linear=target),
                        actual=Motion(linear=round(speed, 3)),
                        deviation=round(abs(target - speed), 3),
                    )
                )
            time.sleep(period_s)
    return root, bag_dir


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="ros2_robot_log", help="log root to write")
    parser.add_argument("--bag", default=None, help="rosbag2 folder (default: OUT_bag/)")
    parser.add_argument("--cycles", type=int, default=60)
    parser.add_argument("--period", type=float, default=0.1, help="decision period, seconds")
    parser.add_argument("--key", default=None, help="Ed25519 key signing the checkpoints")
    parser.add_argument("--record", metavar="BAG", help=argparse.SUPPRESS)  # the recorder
    parser.add_argument("--split", type=float, default=2.0, help="seconds per bag split file")
    args = parser.parse_args(argv)
    if args.record:
        record(Path(args.record), args.split, sys.stdin.buffer)
        return 0
    root, bag_dir = run(args.out, args.bag, args.cycles, args.period, args.key)
    print(f"wrote the log root {root}/ and the rosbag2 recording {bag_dir}/", file=sys.stderr)
    print(f"  trace-audit explain {root} --t 2.0", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
