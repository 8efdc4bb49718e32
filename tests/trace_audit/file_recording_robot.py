"""A robot that cites a single MCAP recording by file name, with sequence numbers: the shape of
``examples/ros2_robot.py`` before issue 42 (profile 1.1 refs, the recording not declared in
the log, written by ``mcap-ros2-support``, which numbers messages). Kept for the tests of
such logs (tests/trace_audit/test_external_evidence.py): they must keep verifying.

    python tests/trace_audit/file_recording_robot.py --out robot.mcap   # also robot_bag/
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

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

SCAN_TOPIC = "/scan"
SCAN_TYPE = "sensor_msgs/msg/LaserScan"
# The ros2msg schema as rosbag2 stores it: the type's definition, then each type it uses.
SCAN_MSGDEF = """\
std_msgs/Header header
float32 angle_min
float32 angle_max
float32 angle_increment
float32 time_increment
float32 scan_time
float32 range_min
float32 range_max
float32[] ranges
float32[] intensities
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
BEAMS = 32
FIELD_OF_VIEW_RAD = math.pi / 2
STOP_BELOW_M = 1.5
SLOW_BELOW_M = 3.0
SPEEDS = {"STOP": 0.0, "SLOW": 0.3, "CONTINUE": 0.8}


def choose(distance_m: float) -> str:
    """The robot's policy: stop near an obstacle, slow down when one is close, else go on."""
    if distance_m < STOP_BELOW_M:
        return "STOP"
    if distance_m < SLOW_BELOW_M:
        return "SLOW"
    return "CONTINUE"


def scan_at(i: int, t_ns: int) -> dict[str, Any]:
    """A LaserScan in which a pallet ahead comes closer and recedes again."""
    obstacle = 0.8 + 4.0 * abs(math.sin(i / 20))
    ranges = [
        round(obstacle if BEAMS // 2 - 3 <= beam <= BEAMS // 2 + 3 else 8.0 + 0.01 * beam, 3)
        for beam in range(BEAMS)
    ]
    return {
        "header": {
            "stamp": {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000},
            "frame_id": "base_laser",
        },
        "angle_min": -FIELD_OF_VIEW_RAD / 2,
        "angle_max": FIELD_OF_VIEW_RAD / 2,
        "angle_increment": FIELD_OF_VIEW_RAD / (BEAMS - 1),
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": 0.1,
        "range_max": 12.0,
        "ranges": ranges,
        "intensities": [],
    }


def decide(cycle: Any, distance: float, ref: Any, beams: tuple[int, int]) -> str:
    """Hand the four layers of one decision to the logger; return the command."""
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
    losers = [c for c in SPEEDS if c != command]
    cycle.action(
        Action(
            command=command,
            alternatives=[
                Alternative(command=c, score=0.1, rejected_because=f"{distance:.2f} m ahead")
                for c in losers
            ],
            rationale=Rationale(
                text=f"obstacle at {distance:.2f} m",
                factors=[
                    Factor(node="obstacle_distance", name="distance", value=distance, unit="m")
                ],
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
    )
    return command


def run(out: str, bag: str | None, cycles: int, period_s: float) -> tuple[Path, Path]:
    """Drive ``cycles`` decisions; return (TRACE log path, recording path)."""
    # mcap-ros2-support's own CDR encoder (the one its Writer uses for the recording)
    from mcap_ros2._dynamic import serialize_dynamic
    from mcap_ros2.writer import Writer

    log_path = Path(out)
    bag_dir = Path(bag) if bag else log_path.with_name(log_path.stem + "_bag")
    bag_dir.mkdir(parents=True, exist_ok=True)
    recording = bag_dir / f"{bag_dir.name}_0.mcap"
    encode = serialize_dynamic(SCAN_TYPE, SCAN_MSGDEF)[SCAN_TYPE]
    speed = SPEEDS["CONTINUE"]
    config = LoggerConfig(fsync_interval_s=None)
    with (
        recording.open("wb") as stream,
        AuditLogger(log_path, robot_id="ros2-bot", period_s=period_s, config=config) as log,
    ):
        writer = Writer(stream)
        schema = writer.register_msgdef(SCAN_TYPE, SCAN_MSGDEF)
        for i in range(cycles):
            t_ns = 1_000_000_000 + round(i * period_s * 1e9)
            scan = scan_at(i, t_ns)
            writer.write_message(SCAN_TOPIC, schema, scan, log_time=t_ns, sequence=i)
            ref = external_ref(recording, SCAN_TOPIC, t_ns, encode(scan), sequence=i)
            beams = (BEAMS // 2 - 3, BEAMS // 2 + 3)
            distance = min(scan["ranges"][beams[0] : beams[1] + 1])
            with log.cycle(t_ns) as cycle:
                command = decide(cycle, distance, ref, beams)
                target = SPEEDS[command]
                speed += 0.6 * (target - speed)
                cycle.execution(
                    Execution(
                        intended=Motion(linear=target),
                        actual=Motion(linear=round(speed, 3)),
                        deviation=round(abs(target - speed), 3),
                    )
                )
        writer.finish()
    return log_path, bag_dir


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="ros2_robot.mcap", help="TRACE log to write")
    parser.add_argument("--bag", default=None, help="recording directory (default: OUT_bag/)")
    parser.add_argument("--cycles", type=int, default=60)
    parser.add_argument("--period", type=float, default=0.1, help="decision period, seconds")
    args = parser.parse_args(argv)
    log_path, bag_dir = run(args.out, args.bag, args.cycles, args.period)
    print(f"wrote {log_path} and the recording {bag_dir}/", file=sys.stderr)
    print(f"  trace-audit explain {log_path} --t 2.0 --evidence {bag_dir}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
