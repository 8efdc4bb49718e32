"""Simulated sensors: a 2-D LiDAR, a forward camera with a detector, a forward ultrasonic.

Each sensor turns ground truth into a noisy reading. Readings are plain arrays and tuples;
what is logged on ``/sensors/...`` is decided by perception (only the returns it used).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.world import HEIGHT_M, WIDTH_M, Actor, World

# LiDAR: 270 deg field of view at 1 deg, 20 m range, 1.5 cm noise (a 2-D safety scanner).
LIDAR_BEAMS = 271
LIDAR_ANGLE_MIN = -math.radians(135.0)
LIDAR_ANGLE_INC = math.radians(1.0)
LIDAR_RANGE_MAX = 20.0
LIDAR_NOISE_M = 0.015
BEAM_ANGLES = LIDAR_ANGLE_MIN + LIDAR_ANGLE_INC * np.arange(LIDAR_BEAMS)

# Camera: 70 deg horizontal field of view, 640 x 480, detector reaching 15 m.
CAMERA_HALF_FOV = math.radians(35.0)
CAMERA_RANGE_M = 15.0
IMAGE_W, IMAGE_H = 640, 480
FOCAL_PX = (IMAGE_W / 2) / math.tan(CAMERA_HALF_FOV)
CAMERA_HEIGHT_M = 0.8
CLASSES = ("person", "forklift", "pallet")
_HEIGHTS = {"person": 1.75, "forklift": 2.2, "pallet": 1.2}
DETECT_P = 0.97
CONFUSION_P = 0.03

# Ultrasonic: +-15 deg cone, 4 m.
US_HALF_ANGLE = math.radians(15.0)
US_RANGE_MAX = 4.0
US_NOISE_M = 0.01


@dataclass(slots=True)
class LidarScan:
    """One scan: measured ranges (inf = no return) and the map's expected ranges."""

    ranges: np.ndarray
    expected: np.ndarray
    truth: np.ndarray  # noise-free ranges, for the other sensors' occlusion tests


@dataclass(frozen=True, slots=True)
class CameraDetection:
    """A detector output: bearing (rad, robot frame), pixel box and class scores."""

    bearing: float
    box: tuple[float, float, float, float]
    scores: tuple[float, float, float]  # in CLASSES order


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


_Rays = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
_RAYS: dict[float, _Rays] = {}


def _rays(heading: float) -> _Rays:
    """Beam directions and their inverses for a heading (cached: the route has two)."""
    rays = _RAYS.get(heading)
    if rays is None:
        ang = BEAM_ANGLES + heading
        dx, dy = np.cos(ang), np.sin(ang)
        dxs = np.where(np.abs(dx) < 1e-12, 1e-12, dx)
        dys = np.where(np.abs(dy) < 1e-12, 1e-12, dy)
        inv_x, inv_y = 1.0 / dxs, 1.0 / dys
        rays = (dx, dy, inv_x[:, None], inv_y[:, None], dxs > 0, dys > 0)
        if len(_RAYS) < 64:
            _RAYS[heading] = rays
    return rays


def _static_ranges(world: World, ox: float, oy: float, heading: float) -> np.ndarray:
    """Ranges to the map (shelves and outer walls) along each beam: the slab method."""
    _, _, inv_xc, inv_yc, pos_x, pos_y = _rays(heading)
    inv_x, inv_y = inv_xc[:, 0], inv_yc[:, 0]
    # Walls: where the ray leaves the warehouse rectangle.
    tx = np.where(pos_x, (WIDTH_M - ox) * inv_x, -ox * inv_x)
    ty = np.where(pos_y, (HEIGHT_M - oy) * inv_y, -oy * inv_y)
    best = np.minimum(tx, ty)
    boxes = world.shelves
    # Only shelves within range can be hit.
    cx = np.clip(ox, boxes[:, 0], boxes[:, 2]) - ox
    cy = np.clip(oy, boxes[:, 1], boxes[:, 3]) - oy
    near = boxes[cx * cx + cy * cy < LIDAR_RANGE_MAX**2]
    if len(near):
        x0 = (near[:, 0] - ox) * inv_xc
        x1 = (near[:, 2] - ox) * inv_xc
        y0 = (near[:, 1] - oy) * inv_yc
        y1 = (near[:, 3] - oy) * inv_yc
        tmin = np.maximum(np.minimum(x0, x1), np.minimum(y0, y1))
        tmax = np.minimum(np.maximum(x0, x1), np.maximum(y0, y1))
        hit = (tmax >= tmin) & (tmin > 0.0)
        t = np.where(hit, tmin, np.inf).min(axis=1)
        best = np.minimum(best, t)
    return best


def _actor_ranges(
    actor: Actor, ox: float, oy: float, heading: float, out: np.ndarray
) -> None:
    """Lower ``out`` where beams hit ``actor`` (a circle, or an oriented box)."""
    rx, ry = actor.x - ox, actor.y - oy
    dist = math.hypot(rx, ry)
    bound = 0.5 * math.hypot(actor.length, actor.width)
    if dist <= bound or dist - bound > LIDAR_RANGE_MAX:
        return
    bearing = _wrap(math.atan2(ry, rx) - heading)
    half = math.asin(min(1.0, bound / dist))
    i0 = max(0, math.ceil((bearing - half - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC))
    i1 = min(LIDAR_BEAMS - 1, math.floor((bearing + half - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC))
    if i1 < i0:
        return
    ang = BEAM_ANGLES[i0 : i1 + 1] + heading
    dx, dy = np.cos(ang), np.sin(ang)
    if actor.kind == "person":
        r = 0.5 * actor.length
        b = dx * rx + dy * ry
        disc = b * b - (dist * dist - r * r)
        t = np.where(disc >= 0.0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    else:
        c, s = math.cos(actor.heading), math.sin(actor.heading)
        # Ray origin and direction in the actor's frame.
        lx, ly = -(c * rx + s * ry), -(-s * rx + c * ry)
        ldx, ldy = c * dx + s * dy, -s * dx + c * dy
        ldx = np.where(np.abs(ldx) < 1e-12, 1e-12, ldx)
        ldy = np.where(np.abs(ldy) < 1e-12, 1e-12, ldy)
        hl, hw = 0.5 * actor.length, 0.5 * actor.width
        x0, x1 = (-hl - lx) / ldx, (hl - lx) / ldx
        y0, y1 = (-hw - ly) / ldy, (hw - ly) / ldy
        tmin = np.maximum(np.minimum(x0, x1), np.minimum(y0, y1))
        tmax = np.minimum(np.maximum(x0, x1), np.maximum(y0, y1))
        t = np.where((tmax >= tmin) & (tmin > 0.0), tmin, np.inf)
    seg = out[i0 : i1 + 1]
    np.minimum(seg, t, out=seg)


def scan_lidar(world: World, rng: np.random.Generator) -> LidarScan:
    """Ray-cast one scan from the robot's pose, with range noise."""
    ox, oy, heading = world.robot_pose()
    expected = _static_ranges(world, ox, oy, heading)
    truth = expected.copy()
    for actor in world.actors:
        _actor_ranges(actor, ox, oy, heading, truth)
    ranges = truth + rng.normal(0.0, LIDAR_NOISE_M, LIDAR_BEAMS)
    ranges[truth > LIDAR_RANGE_MAX] = np.inf
    expected = np.where(expected > LIDAR_RANGE_MAX, np.inf, expected)
    return LidarScan(ranges=ranges, expected=expected, truth=truth)


def beam_of(bearing: float) -> int:
    """Index of the beam nearest to ``bearing`` (robot frame), clipped to the scan."""
    i = round((bearing - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC)
    return min(LIDAR_BEAMS - 1, max(0, i))


def detect_camera(
    world: World, truth_ranges: np.ndarray, rng: np.random.Generator
) -> list[CameraDetection]:
    """Run the simulated detector: visible actors in the field of view, with class scores."""
    ox, oy, heading = world.robot_pose()
    detections = []
    for actor in world.actors:
        rx, ry = actor.x - ox, actor.y - oy
        dist = math.hypot(rx, ry)
        bearing = _wrap(math.atan2(ry, rx) - heading)
        if dist > CAMERA_RANGE_M or abs(bearing) > CAMERA_HALF_FOV or dist < 0.3:
            continue
        size = 0.5 * (actor.length + actor.width)
        if truth_ranges[beam_of(bearing)] < dist - size:  # occluded
            continue
        if rng.random() > DETECT_P:
            continue
        true_i = CLASSES.index(actor.kind)
        if rng.random() < CONFUSION_P:
            true_i = (true_i + 1 + int(rng.integers(0, len(CLASSES) - 1))) % len(CLASSES)
        top = float(rng.uniform(0.6, 0.95))
        split = float(rng.random())
        rest = 1.0 - top
        others = [rest * split, rest * (1.0 - split)]
        scores = [0.0, 0.0, 0.0]
        scores[true_i] = top
        for i in range(len(CLASSES)):
            if i != true_i:
                scores[i] = others.pop()
        b = bearing + float(rng.normal(0.0, 0.005))
        u = IMAGE_W / 2 - FOCAL_PX * math.tan(b)
        half = FOCAL_PX * 0.5 * size / dist
        v_top = IMAGE_H / 2 - FOCAL_PX * (_HEIGHTS[actor.kind] - CAMERA_HEIGHT_M) / dist
        v_bot = IMAGE_H / 2 + FOCAL_PX * CAMERA_HEIGHT_M / dist
        box = (
            max(0.0, u - half),
            max(0.0, v_top),
            min(float(IMAGE_W), u + half),
            min(float(IMAGE_H), v_bot),
        )
        detections.append(
            CameraDetection(b, box, (scores[0], scores[1], scores[2]))
        )
    return detections


def range_ultrasonic(truth_ranges: np.ndarray, rng: np.random.Generator) -> float | None:
    """Nearest echo in the forward cone, or None beyond range."""
    i0, i1 = beam_of(-US_HALF_ANGLE), beam_of(US_HALF_ANGLE)
    nearest = float(truth_ranges[i0 : i1 + 1].min())
    if nearest > US_RANGE_MAX:
        return None
    return max(0.02, nearest + float(rng.normal(0.0, US_NOISE_M)))
