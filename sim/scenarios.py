"""The paper's five evaluation scenarios, as episodes that spawn actors around the robot.

An episode lasts at most ``EPISODE_CYCLES`` cycles; a scenario run for more cycles spawns a
fresh episode every ``EPISODE_CYCLES``. Actors are placed relative to the robot's route, so
scenarios chain one after another wherever the robot happens to be.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from sim.world import Actor, World

EPISODE_CYCLES = 100

PERSON_D = 0.5
FORKLIFT_L, FORKLIFT_W = 2.4, 1.2
PALLET_L, PALLET_W = 1.2, 1.0


def _frame(heading: float) -> tuple[float, float, float, float]:
    """(forward x, forward y, left x, left y) unit vectors for a route heading."""
    c, s = math.cos(heading), math.sin(heading)
    return c, s, -s, c


def _clear_path(world: World) -> list[Actor]:
    actors = []
    for i, (ahead, side) in enumerate(((5.0, 1.45), (9.5, -1.45), (14.0, 1.45))):
        jitter = float(world.rng.uniform(-0.5, 0.5))
        x, y, h = world.along_route(ahead + jitter, side)
        actors.append(Actor("pallet", x, y, PALLET_L, PALLET_W, heading=h, name=f"pallet{i}"))
    return actors


def _ped_crossing(world: World) -> list[Actor]:
    ahead = float(world.rng.uniform(5.5, 6.5))
    speed = float(world.rng.uniform(0.6, 0.8))
    x, y, h = world.along_route(ahead, 1.8)
    _, _, lx, ly = _frame(h)
    delay = float(world.rng.uniform(0.5, 1.5))
    legs = [(delay, 0.0, 0.0), (3.6 / speed, -lx * speed, -ly * speed)]
    return [Actor("person", x, y, PERSON_D, PERSON_D, heading=h, legs=legs, name="walker")]


def _ped_close(world: World) -> list[Actor]:
    # A worker steps out from the shelf and stands picking about 1.5 m in front of the robot,
    # then walks back to the shelf side and stays there.
    ahead = float(world.rng.uniform(1.65, 1.85))
    x, y, h = world.along_route(ahead, float(world.rng.uniform(-0.3, 0.3)))
    _, _, lx, ly = _frame(h)
    side = 1.0 if world.rng.random() < 0.5 else -1.0
    legs = [(7.0, 0.0, 0.0), (2.0, side * lx * 0.7, side * ly * 0.7)]
    return [Actor("person", x, y, PERSON_D, PERSON_D, heading=h, legs=legs, name="worker")]


def _multi_ped(world: World) -> list[Actor]:
    rng = world.rng
    # A: walks towards the robot along the aisle, passing beside it.
    xa, ya, h = world.along_route(float(rng.uniform(9.0, 11.0)), 0.9)
    fx, fy, lx, ly = _frame(h)
    a = Actor("person", xa, ya, PERSON_D, PERSON_D, legs=[(12.0, -fx * 0.9, -fy * 0.9)], name="a")
    # B: crosses the aisle a few metres ahead, after a pause.
    xb, yb, _ = world.along_route(float(rng.uniform(4.5, 5.5)), -1.8)
    b_legs = [(float(rng.uniform(1.5, 2.5)), 0.0, 0.0), (4.5, lx * 0.8, ly * 0.8)]
    b = Actor("person", xb, yb, PERSON_D, PERSON_D, legs=b_legs, name="b")
    # C: stands picking at the shelf side further down the aisle.
    xc, yc, _ = world.along_route(float(rng.uniform(11.0, 13.0)), -1.5)
    c = Actor("person", xc, yc, PERSON_D, PERSON_D, name="c")
    return [a, b, c]


def _forklift(world: World) -> list[Actor]:
    # Head-on down the aisle's centre towards a pick position 4-6 m closer, where it stops
    # to load for the rest of the episode: first a vehicle on a collision course, then an
    # obstacle in a 4 m aisle that leaves no room to pass. The driver also brakes for a
    # robot in the way within 4 m.
    ahead = float(world.rng.uniform(11.0, 13.0))
    speed = float(world.rng.uniform(1.6, 2.0))
    drive_s = float(world.rng.uniform(4.0, 6.0)) / speed
    x, y, h = world.along_route(ahead, float(world.rng.uniform(-0.2, 0.2)))
    fx, fy, _, _ = _frame(h)
    legs = [(drive_s, -fx * speed, -fy * speed), (60.0, 0.0, 0.0)]
    return [
        Actor(
            "forklift",
            x,
            y,
            FORKLIFT_L,
            FORKLIFT_W,
            heading=h + math.pi,
            legs=legs,
            brake_within_m=4.0,
            path_half_width_m=1.5,
            name="forklift",
        )
    ]


@dataclass(frozen=True, slots=True)
class Scenario:
    """One evaluation scenario: its name, the paper's description and how it spawns."""

    name: str
    description: str
    spawn: Callable[[World], list[Actor]]


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("clear_path", "clear path with static objects (pallets) beside it", _clear_path),
        Scenario("ped_crossing", "pedestrian crossing the aisle at medium distance", _ped_crossing),
        Scenario("ped_close", "worker standing about 1.5 m in front of the robot", _ped_close),
        Scenario("multi_ped", "three pedestrians with different trajectories", _multi_ped),
        Scenario(
            "forklift",
            "forklift approaching head-on, then stopping to load in the aisle",
            _forklift,
        ),
    )
}
