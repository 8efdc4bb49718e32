"""Layer 1 tracking: a track's velocity is what it was seen to do, not what the view did."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from sim.perception import VELOCITY_MIN_LOOKS, Perceiver, PerceptionOutput
from sim.scenarios import FORKLIFT_L, FORKLIFT_W, PALLET_L, PALLET_W
from sim.sensors import scan_lidar
from sim.world import Actor, World


def _no_log(topic: str, payload: dict[str, Any]) -> None:
    return None


def _drive(world: World, cycles: int, speed: float = 1.2) -> list[PerceptionOutput]:
    """Drive the robot along its route at ``speed``, LiDAR only; perception every cycle."""
    rng = np.random.default_rng(7)
    perceiver = Perceiver()
    outputs = []
    for k in range(cycles):
        outputs.append(
            perceiver.step(
                cycle=k,
                pose=world.robot_pose(),
                speed=speed,
                scan=scan_lidar(world, rng),
                detections=None,
                us_range=None,
                corridor_length=10.0,
                log_sensor=_no_log,
            )
        )
        world.apply_motion(speed, 0.0, flip=False)
        world.step_actors()
    return outputs


@pytest.mark.parametrize("side", [1.45, -1.45, 1.2])
@pytest.mark.parametrize("seed", [0, 1])
def test_a_pallet_driven_past_is_never_seen_moving(side: float, seed: int) -> None:
    """The centroid of its visible faces slides with the robot; the track stays still."""
    world = World(np.random.default_rng(seed))
    world.robot.s = 10.0
    x, y, h = world.along_route(5.0, side)
    world.actors = [Actor("pallet", x, y, PALLET_L, PALLET_W, heading=h, name="p")]
    outputs = _drive(world, 70)  # from 5 m ahead to 3.4 m behind
    seen = [e for out in outputs for e in out.entities]
    assert len(seen) >= 50
    assert all((e.vx, e.vy) == (0.0, 0.0) for e in seen)
    assert all(e.cls != "forklift" for e in seen)


def test_an_approaching_forklift_is_seen_moving_once_its_track_is_old_enough() -> None:
    world = World(np.random.default_rng(3))
    world.robot.s = 5.0
    x, y, h = world.along_route(14.0, 0.0)
    fx, fy = math.cos(h), math.sin(h)
    legs = [(10.0, -1.8 * fx, -1.8 * fy)]
    world.actors = [
        Actor("forklift", x, y, FORKLIFT_L, FORKLIFT_W, heading=h + math.pi, legs=legs, name="f")
    ]
    outputs = _drive(world, 25)
    tracks = [(k, e) for k, out in enumerate(outputs) for e in out.entities]
    first = tracks[0][0]
    for k, e in tracks:
        if k - first < VELOCITY_MIN_LOOKS - 1:
            # Too few looks: velocity unknown, reported as standing still, never as moving.
            assert (e.vx, e.vy) == (0.0, 0.0)
    late = [e for k, e in tracks if k - first >= 2 * VELOCITY_MIN_LOOKS]
    assert late
    for e in late:
        # Moving towards the robot at about 1.8 m/s, in the world frame.
        along = e.vx * fx + e.vy * fy
        assert along == pytest.approx(-1.8, abs=0.3)
