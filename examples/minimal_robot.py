"""A minimal robot control loop that keeps a TRACE audit trail.

    python examples/minimal_robot.py --out robot.mcap --cycles 50
    trace-audit explain robot.mcap --t 2.0

Each cycle the "robot" reads a range sensor, turns the reading into an entity, derives its
distance and collision risk, chooses STOP / SLOW / CONTINUE, and drives. Every layer goes to
the logger with the sensor reading it came from, so the log explains each choice.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

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
    UsageError,
)

STOP_BELOW_M = 2.0
SLOW_BELOW_M = 4.0


def choose(distance_m: float) -> str:
    """The robot's policy: stop near a person, slow down when one is close, else continue."""
    if distance_m < STOP_BELOW_M:
        return "STOP"
    if distance_m < SLOW_BELOW_M:
        return "SLOW"
    return "CONTINUE"


def run(out: str, cycles: int, period_s: float, *, announce: bool = False) -> None:
    speeds = {"STOP": 0.0, "SLOW": 0.4, "CONTINUE": 1.0}
    actual_speed = 1.0
    config = LoggerConfig(fsync_interval_s=None)
    with AuditLogger(out, robot_id="demo-bot", period_s=period_s, config=config) as log:
        for i in range(cycles):
            t_ns = round(i * period_s * 1e9)
            # A person walks towards the robot and away again.
            distance = 1.0 + 4.0 * abs(math.sin(i / 15))
            with log.cycle(t_ns) as cycle:
                ref = cycle.sensor("/sensors/range", {"range_m": round(distance, 3)})
                cycle.perception(
                    Perception(
                        entities=[
                            Entity(
                                id="person_1",
                                cls="person",
                                pose=Pose(position=(distance, 0.0, 0.0)),
                                confidence={"person": 0.9, "pallet": 0.1},
                                evidence=[Evidence(sensor="range", weight=1.0, ref=ref)],
                            )
                        ],
                        sensors_used=["range"],
                    )
                )
                risk = round(min(1.0, 1.4 / distance), 3)
                cycle.belief(
                    Belief(
                        nodes=[
                            BeliefNode(id="person_1", kind="entity", p=0.9, entity="person_1"),
                            BeliefNode(
                                id="person_1.distance",
                                kind="state",
                                p=0.95,
                                value=round(distance, 3),
                                unit="m",
                            ),
                            BeliefNode(id="person_1.risk", kind="state", p=0.9, value=risk),
                        ],
                        edges=[
                            BeliefEdge(
                                parent="person_1",
                                child="person_1.distance",
                                p=0.95,
                                rule="range_to_distance",
                            ),
                            BeliefEdge(
                                parent="person_1.distance",
                                child="person_1.risk",
                                p=0.9,
                                rule="risk_from_distance",
                            ),
                        ],
                    )
                )
                command = choose(distance)
                cycle.action(
                    Action(
                        command=command,
                        alternatives=[
                            Alternative(command=c, score=0.0, rejected_because="policy threshold")
                            for c in speeds
                            if c != command
                        ],
                        rationale=Rationale(
                            text=f"person at {distance:.2f} m",
                            factors=[
                                Factor(
                                    node="person_1.distance",
                                    name="distance",
                                    value=round(distance, 3),
                                    unit="m",
                                )
                            ],
                        ),
                        counterfactuals=_counterfactuals(command),
                    )
                )
                target = speeds[command]
                actual_speed += 0.6 * (target - actual_speed)  # actuator lag
                cycle.execution(
                    Execution(
                        intended=Motion(linear=target),
                        actual=Motion(linear=round(actual_speed, 4)),
                        deviation=round(abs(target - actual_speed), 4),
                    )
                )
            if announce:
                print(cycle.cycle, flush=True)  # the crash test reads what was committed
            if period_s and announce:
                time.sleep(period_s)


def _counterfactuals(command: str) -> list[Counterfactual]:
    node = "person_1.distance"
    if command == "STOP":
        return [
            Counterfactual(
                factor=node, comparison=">=", threshold=STOP_BELOW_M, would_select="SLOW"
            )
        ]
    if command == "SLOW":
        return [
            Counterfactual(
                factor=node, comparison="<", threshold=STOP_BELOW_M, would_select="STOP"
            ),
            Counterfactual(
                factor=node, comparison=">=", threshold=SLOW_BELOW_M, would_select="CONTINUE"
            ),
        ]
    return [
        Counterfactual(factor=node, comparison="<", threshold=SLOW_BELOW_M, would_select="SLOW")
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="robot.mcap", help="log file (.mcap) or log root")
    parser.add_argument("--cycles", type=int, default=50)
    parser.add_argument("--period", type=float, default=0.1, help="cycle period in seconds")
    parser.add_argument(
        "--announce", action="store_true", help="print each committed cycle and run in real time"
    )
    args = parser.parse_args(argv)
    try:
        run(args.out, args.cycles, args.period, announce=args.announce)
    except UsageError as err:  # a set-up error (an --out log that exists): one line, exit 2
        print(f"minimal_robot: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
