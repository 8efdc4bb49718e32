"""A pick-and-place arm that keeps a TRACE audit trail: execution as named actuator channels.

    python examples/pick_and_place_arm.py --out arm.mcap
    trace-audit explain arm.mcap --t 6.5

A four-joint arm with a parallel gripper moves parts from a conveyor to a bin. Each cycle it
reads its wrist camera (the part, and a person's hand when one reaches into the workspace)
and its wrist force-torque sensor (the grip force), and chooses:

- HALT    when a hand is closer than 0.30 m,
- RETRY   when the grip holds less than 60 % of the commanded force (the part slips),
- RELEASE when the part is within 2 cm of the bin,
- GRASP   otherwise (close on the part and carry it).

There is no planar motion here: the execution record logs every joint velocity (rad/s),
the gripper force (N) and the end-effector speed (m/s) as ``ActuatorChannel``s, intended vs
actual, so ``trace-audit explain`` shows the arm's own quantities in the arm's own units.
The simulation is deterministic (``--seed``) and runs in well under a second by default.
"""

from __future__ import annotations

import argparse
import math
import random
import sys

from trace_runtime import (
    Action,
    ActuatorChannel,
    Alternative,
    AuditLogger,
    Belief,
    BeliefEdge,
    BeliefNode,
    ComplianceCheck,
    Counterfactual,
    Entity,
    Evidence,
    EvidenceRef,
    Execution,
    Factor,
    LoggerConfig,
    Perception,
    Pose,
    Rationale,
    Region,
)

HALT_HAND_M = 0.30
SLIP_RATIO = 0.6
PLACE_M = 0.02
GRIP_N = 20.0
MAX_GRIP_N = 40.0
EE_SPEED_NEAR_HAND = 0.05  # m/s allowed while a hand is within 0.5 m
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist")
COMMANDS = ("GRASP", "RETRY", "RELEASE", "HALT")
CARRY_CYCLES = 30  # cycles to carry a part from the conveyor to the bin


def choose(hand_m: float | None, grip_ratio: float, to_place_m: float) -> str:
    """The arm's policy, in priority order."""
    if hand_m is not None and hand_m < HALT_HAND_M:
        return "HALT"
    if grip_ratio < SLIP_RATIO:
        return "RETRY"
    if to_place_m < PLACE_M:
        return "RELEASE"
    return "GRASP"


class Arm:
    """The simulated arm, its part and the person who sometimes reaches in."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        self.part = 0
        self.progress = 0  # carry cycles done for this part
        self.grip_n = 0.0  # measured grip force
        self.joint_vel = [0.0] * len(JOINTS)
        self.slip_at = self.rng.randrange(5, CARRY_CYCLES - 5)

    def hand_distance(self, i: int) -> float | None:
        """A hand reaches in around t = 6 s and t = 16 s (at 10 Hz), else is not seen."""
        for centre in (65, 165):
            if abs(i - centre) <= 8:
                return round(0.15 + 0.05 * abs(i - centre), 3)
        return None

    def to_place_m(self) -> float:
        return round(max(0.0, 0.6 * (1 - self.progress / CARRY_CYCLES)), 4)

    def step(self, command: str) -> tuple[list[float], float]:
        """Apply ``command``; return the intended joint velocities and gripper force."""
        if command == "HALT":  # stop moving, keep holding what is in the gripper
            target_vel, target_grip = [0.0] * len(JOINTS), held_grip(self)
        elif command == "RETRY":
            target_vel, target_grip = [0.0] * len(JOINTS), GRIP_N
        elif command == "RELEASE":
            target_vel, target_grip = [0.0] * len(JOINTS), 0.0
        else:
            phase = math.pi * self.progress / CARRY_CYCLES
            target_vel = [round(0.4 * math.sin(phase + k), 4) for k in range(len(JOINTS))]
            target_grip = GRIP_N
        # Actuator lag, and a grip that slips once per part until it is re-grasped.
        self.joint_vel = [
            v + 0.5 * (t - v) for v, t in zip(self.joint_vel, target_vel, strict=True)
        ]
        slipping = command == "GRASP" and self.progress == self.slip_at
        self.grip_n = (
            0.3 * target_grip if slipping else self.grip_n + 0.7 * (target_grip - self.grip_n)
        )
        if command == "GRASP":
            self.progress += 1
        elif command == "RETRY":
            self.slip_at = -1  # re-grasped firmly
        elif command == "RELEASE":
            self.part += 1
            self.progress = 0
            self.slip_at = self.rng.randrange(5, CARRY_CYCLES - 5)
        return target_vel, target_grip


def held_grip(arm: Arm) -> float:
    """The force a HALT holds: whatever the gripper has now (a halted arm must not drop the
    part), as the action and the execution record both state it."""
    return round(arm.grip_n, 3)


def ee_speed(joint_vel: list[float]) -> float:
    """End-effector speed from joint velocities (a fixed 0.35 m lever per joint)."""
    return round(0.35 * math.sqrt(sum(v * v for v in joint_vel)), 4)


def run(out: str, cycles: int, period_s: float, seed: int) -> None:
    arm = Arm(seed)
    config = LoggerConfig(fsync_interval_s=None)
    with AuditLogger(out, robot_id="arm-1", period_s=period_s, config=config) as log:
        grip_ratio = 1.0
        for i in range(cycles):
            t_ns = round(i * period_s * 1e9)
            hand_m = arm.hand_distance(i)
            to_place = arm.to_place_m()
            with log.cycle(t_ns) as cycle:
                camera = cycle.sensor("/sensors/wrist_camera", _camera_frame(arm, hand_m))
                ft = cycle.sensor(
                    "/sensors/force_torque",
                    {"force_n": [0.0, 0.0, round(arm.grip_n, 3)], "torque_nm": [0.0, 0.0, 0.0]},
                )
                grip_ratio = round(arm.grip_n / GRIP_N, 3) if arm.progress else 1.0
                cycle.perception(_perception(arm, hand_m, camera, ft))
                cycle.belief(_belief(arm, hand_m, grip_ratio, to_place))
                command = choose(hand_m, grip_ratio, to_place)
                cycle.action(_action(command, arm, hand_m, grip_ratio, to_place))
                target_vel, target_grip = arm.step(command)
                cycle.execution(_execution(command, hand_m, target_vel, target_grip, arm))


def _camera_frame(arm: Arm, hand_m: float | None) -> dict[str, object]:
    detections: list[dict[str, object]] = [
        {"label": "part", "box": [300, 220, 360, 270], "score": 0.97, "depth_m": arm.to_place_m()}
    ]
    if hand_m is not None:
        detections.append(
            {"label": "hand", "box": [40, 60, 180, 200], "score": 0.93, "depth_m": hand_m}
        )
    return {"frame": "wrist_camera", "detections": detections}


def _perception(arm: Arm, hand_m: float | None, camera: EvidenceRef, ft: EvidenceRef) -> Perception:
    part = f"part_{arm.part}"
    entities = [
        Entity(
            id=part,
            cls="part",
            pose=Pose(position=(arm.to_place_m(), 0.0, 0.05), frame="bin"),
            confidence={"part": 0.97, "debris": 0.03},
            evidence=[
                Evidence(
                    sensor="wrist_camera",
                    weight=1.0,
                    region=Region(kind="pixels", values=[300, 220, 360, 270]),
                    ref=camera,
                )
            ],
        ),
        Entity(
            id="grip_contact",
            cls="contact",
            pose=Pose(position=(0.0, 0.0, 0.0), frame="gripper"),
            confidence={"contact": 0.95 if arm.grip_n > 1.0 else 0.05},
            evidence=[Evidence(sensor="force_torque", weight=1.0, ref=ft)],
        ),
    ]
    if hand_m is not None:
        entities.append(
            Entity(
                id="hand_1",
                cls="hand",
                pose=Pose(position=(hand_m, 0.0, 0.0), frame="wrist_camera"),
                confidence={"hand": 0.93, "part": 0.07},
                evidence=[
                    Evidence(
                        sensor="wrist_camera",
                        weight=1.0,
                        region=Region(kind="pixels", values=[40, 60, 180, 200]),
                        ref=camera,
                    )
                ],
            )
        )
    return Perception(entities=entities, sensors_used=["wrist_camera", "force_torque"])


def _belief(arm: Arm, hand_m: float | None, grip_ratio: float, to_place: float) -> Belief:
    part = f"part_{arm.part}"
    nodes = [
        BeliefNode(id=part, kind="entity", p=0.97, entity=part),
        BeliefNode(id="grip_contact", kind="entity", p=0.95, entity="grip_contact"),
        BeliefNode(
            id="grip.force",
            kind="state",
            label="grip force",
            p=0.95,
            value=round(arm.grip_n, 3),
            unit="N",
        ),
        BeliefNode(
            id="grip.ratio", kind="state", label="grip held / commanded", p=0.9, value=grip_ratio
        ),
        BeliefNode(
            id="part.to_bin", kind="state", label="part to bin", p=0.9, value=to_place, unit="m"
        ),
    ]
    edges = [
        BeliefEdge(parent="grip_contact", child="grip.force", p=0.95, rule="force_torque_to_grip"),
        BeliefEdge(parent="grip.force", child="grip.ratio", p=0.9, rule="grip_over_commanded"),
        BeliefEdge(parent=part, child="part.to_bin", p=0.9, rule="camera_depth_to_bin"),
    ]
    if hand_m is not None:
        nodes += [
            BeliefNode(id="hand_1", kind="entity", p=0.93, entity="hand_1"),
            BeliefNode(
                id="hand.distance",
                kind="state",
                label="hand distance",
                p=0.9,
                value=hand_m,
                unit="m",
            ),
        ]
        edges.append(BeliefEdge(parent="hand_1", child="hand.distance", p=0.9, rule="camera_depth"))
    return Belief(nodes=nodes, edges=edges)


def _grip_command(command: str, arm: Arm) -> float:
    """The gripper force the command asks for (N): the same figure the execution record
    gives as the gripper's intended force."""
    if command in ("GRASP", "RETRY"):
        return GRIP_N
    return held_grip(arm) if command == "HALT" else 0.0


def _action(
    command: str, arm: Arm, hand_m: float | None, grip_ratio: float, to_place: float
) -> Action:
    factors = [
        Factor(node="grip.ratio", name="grip ratio", value=grip_ratio),
        Factor(node="part.to_bin", name="part to bin", value=to_place, unit="m"),
    ]
    if hand_m is not None:
        factors.insert(
            0, Factor(node="hand.distance", name="hand distance", value=hand_m, unit="m")
        )
    counterfactuals = _counterfactuals(command, hand_m, grip_ratio, to_place)
    return Action(
        command=command,
        parameters={"grip_force_n": _grip_command(command, arm)},
        alternatives=[
            Alternative(
                command=c, score=0.0, rejected_because="lower priority rule or condition unmet"
            )
            for c in COMMANDS
            if c != command
        ],
        rationale=Rationale(text=_why(command, hand_m, grip_ratio, to_place), factors=factors),
        counterfactuals=counterfactuals,
        counterfactuals_none_applicable=not counterfactuals,
    )


def _why(command: str, hand_m: float | None, grip_ratio: float, to_place: float) -> str:
    if command == "HALT":
        return f"hand {hand_m:.2f} m from the gripper (< {HALT_HAND_M} m)"
    if command == "RETRY":
        return f"grip holds {grip_ratio:.0%} of the commanded force: the part slips"
    if command == "RELEASE":
        return f"part {to_place * 100:.1f} cm from the bin"
    return "part held; carrying it to the bin"


def _counterfactuals(
    command: str, hand_m: float | None, grip_ratio: float, to_place: float
) -> list[Counterfactual]:
    """Each factor's threshold, and what the policy itself would choose across it."""
    out = []
    thresholds = {"hand.distance": HALT_HAND_M, "grip.ratio": SLIP_RATIO, "part.to_bin": PLACE_M}
    values = {"hand.distance": hand_m, "grip.ratio": grip_ratio, "part.to_bin": to_place}
    for node, threshold in thresholds.items():
        value = values[node]
        if value is None:
            continue  # no hand seen: nothing to put across the threshold
        below = value < threshold
        what_if = dict(values, **{node: threshold if below else threshold / 2})
        other = choose(
            what_if["hand.distance"], what_if["grip.ratio"] or 0.0, what_if["part.to_bin"] or 0.0
        )
        if other != command:
            out.append(
                Counterfactual(
                    factor=node,
                    comparison=">=" if below else "<",
                    threshold=threshold,
                    would_select=other,
                )
            )
    return out


def _execution(
    command: str,
    hand_m: float | None,
    target_vel: list[float],
    target_grip: float,
    arm: Arm,
) -> Execution:
    channels = [
        ActuatorChannel(
            name=name,
            unit="rad/s",
            intended=want,
            actual=round(got, 4),
            deviation=round(abs(got - want), 4),
        )
        for name, want, got in zip(JOINTS, target_vel, arm.joint_vel, strict=True)
    ]
    channels.append(
        ActuatorChannel(
            name="gripper_force",
            unit="N",
            intended=target_grip,
            actual=round(arm.grip_n, 3),
            deviation=round(abs(arm.grip_n - target_grip), 3),
        )
    )
    want_speed, got_speed = ee_speed(target_vel), ee_speed(arm.joint_vel)
    channels.append(
        ActuatorChannel(
            name="ee_speed",
            unit="m/s",
            intended=want_speed,
            actual=got_speed,
            deviation=round(abs(got_speed - want_speed), 4),
        )
    )
    near = hand_m is not None and hand_m < 0.5
    checks = [
        ComplianceCheck(
            rule="max_grip_force",
            passed=arm.grip_n <= MAX_GRIP_N,
            value=round(arm.grip_n, 3),
            limit=MAX_GRIP_N,
        ),
        ComplianceCheck(
            rule="ee_speed_near_hand",
            passed=not near or got_speed <= EE_SPEED_NEAR_HAND,
            value=got_speed,
            limit=EE_SPEED_NEAR_HAND if near else None,
            detail="hand within 0.5 m" if near else "no hand near",
        ),
    ]
    flags = ["slip"] if command == "RETRY" else []
    return Execution(
        channels=channels,
        deviation=round(abs(got_speed - want_speed), 4),
        deviation_unit="m/s",
        checks=checks,
        flags=flags,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="arm.mcap", help="log file (.mcap) or log root")
    parser.add_argument("--cycles", type=int, default=240, help="cycles to run (default 240: 24 s)")
    parser.add_argument("--period", type=float, default=0.1, help="cycle period in seconds")
    parser.add_argument("--seed", type=int, default=7, help="seed of the simulated slips")
    args = parser.parse_args(argv)
    run(args.out, args.cycles, args.period, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
