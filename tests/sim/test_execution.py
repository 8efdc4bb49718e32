"""The compliance monitor and the executive: a failed check means the robot did wrong, and
a path change is a turn at bounded yaw rate."""

from __future__ import annotations

import itertools
import math

import numpy as np

from sim.belief import BeliefGraph, Node
from sim.execution import MAX_YAW_RATE, STOP_SPEED, Actuator, Steering
from sim.policy import CONTINUE, REROUTE, SLOW, STOP
from sim.world import POSE_YAW_STEP, World


def _person_at(d: float) -> BeliefGraph:
    return BeliefGraph(
        (
            Node("ped_1", "entity", "person", 0.9, "person", None, "ped_1"),
            Node("ped_1.distance", "state", "distance", 0.97, d, "m"),
        ),
        (),
    )


def _checks(act: Actuator, command: str, t: float, graph: BeliefGraph) -> dict[str, bool]:
    return {c.rule: c.passed for c in act.step(command, t, graph).checks}


def _cruising(seed: int = 0) -> Actuator:
    act = Actuator(np.random.default_rng(seed))
    for k in range(30):
        act.step(CONTINUE, k * 0.1, _person_at(20.0))
    return act


def test_cruising_past_a_person_within_3_m_fails_the_speed_limit() -> None:
    act = _cruising()
    assert _checks(act, CONTINUE, 3.0, _person_at(2.5))["person_speed_limit"] is False


def test_braking_towards_the_limit_at_the_actuators_rate_complies() -> None:
    act = _cruising()
    for k in range(10):
        checks = _checks(act, SLOW, 3.0 + k * 0.1, _person_at(2.5))
        assert checks["person_speed_limit"], (k, act.linear)
    assert act.linear <= 0.5


def test_a_stopped_robot_passes_stop_response_over_its_noise_floor() -> None:
    for seed in range(5):
        act = _cruising(seed)
        speeds = []
        for k in range(200):
            checks = _checks(act, STOP, 3.0 + k * 0.1, _person_at(20.0))
            speeds.append(act.linear)
            assert checks.get("stop_response", True), (seed, k, act.linear)
        assert max(speeds[20:]) < STOP_SPEED


def test_a_reroute_turns_the_robot_around_at_bounded_yaw_rate() -> None:
    world = World(np.random.default_rng(1))
    world.robot.s = 20.0
    steering = Steering()
    act = Actuator(np.random.default_rng(2))
    start_direction = world.robot.direction
    headings = [world.robot_pose()[2]]
    empty = BeliefGraph((), ())
    for k in range(120):
        yaw, lateral = world.robot.offsets()
        want = steering.steer(
            REROUTE if k < 3 else CONTINUE,
            heading_error=yaw,
            lateral=lateral,
            direction=world.robot.direction,
        )
        assert abs(want[1]) <= MAX_YAW_RATE
        executed = act.step(CONTINUE, k * 0.1, empty, want)
        world.apply_motion(act.linear, act.angular)
        headings.append(world.robot_pose()[2])
        assert executed.intended == want
    assert world.robot.direction == -start_direction
    steps = [
        abs(math.atan2(math.sin(b - a), math.cos(b - a))) for a, b in itertools.pairwise(headings)
    ]
    # Bounded by the yaw rate (plus the actuator's noise and the pose's grid), never a flip.
    assert max(steps) < (MAX_YAW_RATE + 0.1) * 0.1 + POSE_YAW_STEP
    assert abs(world.robot.offsets()[0]) < 0.2
