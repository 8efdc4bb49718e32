"""The LiDAR's cached ray geometry gives exactly what the textbook slab test gives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import sensors
from sim.sensors import BEAM_ANGLES, LIDAR_RANGE_MAX, scan_lidar
from sim.world import HEIGHT_M, WIDTH_M, Actor, World


def _slab(ox: float, oy: float, dx: np.ndarray, dy: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Every beam against every box: the entry range of the first hit, inf if none."""
    dxs = np.where(np.abs(dx) < 1e-12, 1e-12, dx)
    dys = np.where(np.abs(dy) < 1e-12, 1e-12, dy)
    x0 = (boxes[:, 0] - ox) / dxs[:, None]
    x1 = (boxes[:, 2] - ox) / dxs[:, None]
    y0 = (boxes[:, 1] - oy) / dys[:, None]
    y1 = (boxes[:, 3] - oy) / dys[:, None]
    tmin = np.maximum(np.minimum(x0, x1), np.minimum(y0, y1))
    tmax = np.minimum(np.maximum(x0, x1), np.maximum(y0, y1))
    hit = (tmax >= tmin) & (tmin > 0.0)
    out: np.ndarray = np.where(hit, tmin, np.inf).min(axis=1)
    return out


def _reference_map(world: World, ox: float, oy: float, heading: float) -> np.ndarray:
    """Ranges to the walls and to every shelf within LiDAR range, written the plain way."""
    ang = BEAM_ANGLES + heading
    dx, dy = np.cos(ang), np.sin(ang)
    dxs = np.where(np.abs(dx) < 1e-12, 1e-12, dx)
    dys = np.where(np.abs(dy) < 1e-12, 1e-12, dy)
    inv_x, inv_y = 1.0 / dxs, 1.0 / dys
    walls = np.minimum(
        np.where(dxs > 0, (WIDTH_M - ox) * inv_x, -ox * inv_x),
        np.where(dys > 0, (HEIGHT_M - oy) * inv_y, -oy * inv_y),
    )
    boxes = world.shelves
    cx = np.clip(ox, boxes[:, 0], boxes[:, 2]) - ox
    cy = np.clip(oy, boxes[:, 1], boxes[:, 3]) - oy
    near = boxes[cx * cx + cy * cy < LIDAR_RANGE_MAX**2]
    if not len(near):
        return walls
    # Multiplying by the inverse, as the fast path does (one rounding less than dividing).
    x0, x1 = (near[:, 0] - ox) * inv_x[:, None], (near[:, 2] - ox) * inv_x[:, None]
    y0, y1 = (near[:, 1] - oy) * inv_y[:, None], (near[:, 3] - oy) * inv_y[:, None]
    tmin = np.maximum(np.minimum(x0, x1), np.minimum(y0, y1))
    tmax = np.minimum(np.maximum(x0, x1), np.maximum(y0, y1))
    shelves = np.where((tmax >= tmin) & (tmin > 0.0), tmin, np.inf).min(axis=1)
    out: np.ndarray = np.minimum(walls, shelves)
    return out


def _as_seen(ranges: np.ndarray) -> np.ndarray:
    """What a scan can tell apart: every range beyond the LiDAR's reach is no return."""
    return np.where(ranges > LIDAR_RANGE_MAX, np.inf, ranges)


@pytest.mark.parametrize("heading", [0.0, math.pi, 0.3, -2.0])
@pytest.mark.parametrize("oy", [7.0, 13.0, 4.0])
def test_static_ranges_match_the_plain_slab_test_bit_for_bit(heading: float, oy: float) -> None:
    world = World(np.random.default_rng(0))
    rng = np.random.default_rng(1)
    for ox in [*rng.uniform(0.5, 49.5, 60).tolist(), 5.0, 24.0, 25.0, 45.0]:
        rays = sensors._rays(heading, oy, world.shelves)
        fast = sensors._static_ranges(rays, ox, oy)
        slow = _reference_map(world, ox, oy, heading)
        assert np.array_equal(_as_seen(fast), _as_seen(slow)), (ox, oy, heading)


def _reference_actor(actor: Actor, pose: tuple[float, float, float]) -> np.ndarray:
    """Range to ``actor`` along every beam (inf where it is missed)."""
    ox, oy, heading = pose
    ang = BEAM_ANGLES + heading
    dx, dy = np.cos(ang), np.sin(ang)
    rx, ry = actor.x - ox, actor.y - oy
    if actor.kind == "person":
        r, dist = 0.5 * actor.length, math.hypot(rx, ry)
        b = dx * rx + dy * ry
        disc = b * b - (dist * dist - r * r)
        t = b - np.sqrt(np.maximum(disc, 0.0))
        out: np.ndarray = np.where((disc >= 0.0) & (t > 0.0), t, np.inf)  # ahead of the robot
        return out
    c, s = math.cos(actor.heading), math.sin(actor.heading)
    # Rays in the actor's frame: the box is axis-aligned there, centred on the origin.
    lx, ly = -(c * rx + s * ry), -(-s * rx + c * ry)
    hl, hw = 0.5 * actor.length, 0.5 * actor.width
    box = np.array([[-hl, -hw, hl, hw]])
    return _slab(lx, ly, c * dx + s * dy, -s * dx + c * dy, box)


@pytest.mark.parametrize("few", [0, 1000])  # numpy for every actor, or plain floats
def test_scan_sees_actors_as_the_plain_ray_test_does(
    few: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sensors, "_FEW_BEAMS", few)
    rng = np.random.default_rng(7)
    world = World(np.random.default_rng(3))
    for _ in range(40):
        world.robot.s = float(rng.uniform(0.0, world.route.length))
        world.robot.direction = int(rng.choice([-1, 1]))
        pose = world.robot_pose()
        world.actors = []
        for kind, length, width in (
            ("person", 0.5, 0.5),
            ("pallet", 1.2, 1.0),
            ("forklift", 2.4, 1.2),
        ):
            for _ in range(2):
                x, y, h = world.along_route(
                    float(rng.uniform(0.8, 16.0)), float(rng.uniform(-1.8, 1.8))
                )
                world.actors.append(
                    Actor(
                        kind,
                        x,
                        y,
                        length,
                        width,
                        heading=h + float(rng.choice([0.0, math.pi, 0.4])),
                    )
                )
        scan = scan_lidar(world, np.random.default_rng(0))
        expected = _reference_map(world, *pose)
        for actor in world.actors:
            dist = math.hypot(actor.x - pose[0], actor.y - pose[1])
            if dist > 0.5 * math.hypot(actor.length, actor.width):  # not on top of the robot
                expected = np.minimum(expected, _reference_actor(actor, pose))
        assert np.array_equal(_as_seen(scan.truth), _as_seen(expected))


def test_a_turning_robot_sees_the_plain_slab_test_through_cache_turnover() -> None:
    """A new (heading, y) almost every scan, more than the caches hold, with repeats."""
    world = World(np.random.default_rng(0))
    rng = np.random.default_rng(5)
    poses = [
        (
            float(rng.uniform(0.5, 49.5)),
            round(float(rng.uniform(5.6, 8.4)), 2),
            float(rng.choice([0.0, math.pi])) + round(float(rng.uniform(-1.6, 1.6)), 2),
        )
        for _ in range(150)
    ]
    for ox, oy, heading in poses + poses[::-1]:
        fast = sensors._static_ranges(sensors._rays(heading, oy, world.shelves), ox, oy)
        slow = _reference_map(world, ox, oy, heading)
        assert np.array_equal(_as_seen(fast), _as_seen(slow)), (ox, oy, heading)
