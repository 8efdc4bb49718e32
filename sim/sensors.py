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


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class CameraDetection:
    """A detector output: bearing (rad, robot frame), pixel box and class scores."""

    bearing: float
    box: tuple[float, float, float, float]
    scores: tuple[float, float, float]  # in CLASSES order


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


_Local = tuple[np.ndarray, np.ndarray, list[float], list[float]]


@dataclass(slots=True)
class _Beams:
    """Beam directions for one heading (headings lie on a grid, so they repeat), and the
    parts of every scan's slab tests that depend on the heading (and the map) alone.

    Directions closer than 1e-12 to an axis are nudged off it, so every slab test divides
    by a non-zero component."""

    dx: np.ndarray
    dy: np.ndarray
    dx_list: list[float]
    dy_list: list[float]
    inv_x: np.ndarray
    inv_y: np.ndarray
    wall_x: np.ndarray  # (2, 2, beams): the x bounds of the two wall rows (see _Table)
    shelf_x: np.ndarray  # (2, shelves, beams): the x bound of each shelf the beam enters
    # through (x0 or x1, by the beam's direction), and the one it leaves through
    local: dict[float, _Local]  # see _local_dirs


@dataclass(frozen=True, slots=True)
class _Shelves:
    """The static map, each shelf bound spread over one row per shelf and one column per
    beam: numpy is several times faster on arrays of one shape than when it broadcasts a
    column across a row."""

    boxes: tuple[tuple[float, float, float, float], ...]
    x0: np.ndarray  # (shelves, beams)
    y0: np.ndarray
    x1: np.ndarray
    y1: np.ndarray


@dataclass(frozen=True, slots=True)
class _Table:
    """The slab tests of one scan, one row per obstacle and one column per beam, so that a
    scan is a handful of whole-array steps and a minimum across rows.

    Row 0 is the wall each beam leaves through in x, row 1 the wall it meets in y, then one
    row per shelf in range. Each wall is written as a slab test whose other bounds are
    infinite, so it yields exactly the wall's range: ``(x - ox) * inv_x`` for the x wall,
    ``wall_y`` for the y wall. A (beam, shelf) pair that cannot hit (its y-slab is behind
    the robot, or starts beyond the LiDAR's range) enters its y-slab at +inf and leaves it
    at -inf, so it never hits. Every other test is the textbook slab test's arithmetic, and
    the minimum of a set of floats does not depend on the order it is taken in, so a beam's
    range is bit for bit what a direct test of every beam against every shelf in range gives.
    """

    x: np.ndarray  # (2, rows, beams): the x bound entered through, the x bound left through
    inv_x: np.ndarray  # (beams,)
    y_in: np.ndarray  # (rows, beams): ranges at which the beam enters and leaves the y-slab
    y_out: np.ndarray
    ahead: bool  # every y-slab that can hit starts ahead of the robot (so t_in > 0 holds)


@dataclass(slots=True)
class _Rays:
    """What does not move with ``x``, for one (heading, y, map): per (heading, y) the
    y-slabs of the shelves and the side walls are fixed, and a scan only recomputes the
    x-slabs. The robot turns at a bounded rate, so a new pose comes every cycle of a turn:
    an entry holds only what its tables need, worked out for the shelves in range."""

    beams: _Beams
    shelf: _Shelves
    oy: float
    wall_y: np.ndarray  # (beams,): range to the wall the beam meets in y
    cy2: tuple[float, ...]  # squared y-distance to each shelf
    by_near: dict[tuple[bool, ...], _Table]  # the table of the shelves in range
    last: tuple[float, np.ndarray] | None  # the last scan's x and its ranges (a robot stands)


_SHELVES: dict[bytes, _Shelves] = {}
_BEAMS: dict[tuple[float, bytes], _Beams] = {}
_RAYS: dict[tuple[float, float, bytes], _Rays] = {}


def _shelves(key: bytes, shelves: np.ndarray) -> _Shelves:
    """The cached row-per-shelf layout of ``shelves`` (``key`` its bytes)."""
    found = _SHELVES.get(key)
    if found is None:
        cols = [np.repeat(shelves[:, k : k + 1], LIDAR_BEAMS, axis=1) for k in range(4)]
        boxes = tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in shelves)
        found = _Shelves(boxes, cols[0], cols[1], cols[2], cols[3])
        if len(_SHELVES) >= 8:
            del _SHELVES[next(iter(_SHELVES))]
        _SHELVES[key] = found
    return found


def _beams(heading: float, shelf: _Shelves, map_key: bytes) -> _Beams:
    """The cached beam directions of ``heading`` (``shelf`` the map, ``map_key`` its bytes)."""
    key = (heading, map_key)
    beams = _BEAMS.get(key)
    if beams is not None:
        return beams
    ang = BEAM_ANGLES + heading
    dx, dy = np.cos(ang), np.sin(ang)
    dxs = np.where(np.abs(dx) < 1e-12, 1e-12, dx)
    dys = np.where(np.abs(dy) < 1e-12, 1e-12, dy)
    inv_x = 1.0 / dxs
    ahead_x = inv_x > 0.0
    forward = np.where(ahead_x, np.inf, -np.inf)  # the x at infinity ahead of each beam
    # Row 0, the x wall: t_in = (x_wall - ox) * inv_x; the other bounds never bind.
    # Row 1, the y wall: (x at infinity behind - ox) * inv_x = -inf, so t_in = wall_y.
    wall_x: np.ndarray = np.array(((np.where(ahead_x, WIDTH_M, 0.0), -forward), (forward, forward)))
    shelf_x: np.ndarray = np.array(
        (np.where(ahead_x, shelf.x0, shelf.x1), np.where(ahead_x, shelf.x1, shelf.x0))
    )
    beams = _Beams(dx, dy, dx.tolist(), dy.tolist(), inv_x, 1.0 / dys, wall_x, shelf_x, {})
    if len(_BEAMS) >= 1024:  # a turn on the 0.01 rad grid passes ~315 of them
        del _BEAMS[next(iter(_BEAMS))]
    _BEAMS[key] = beams
    return beams


def _rays(heading: float, oy: float, shelves: np.ndarray) -> _Rays:
    """The cached ray geometry of ``heading`` from height ``oy`` among ``shelves``."""
    map_key = shelves.tobytes()
    key = (heading, oy, map_key)
    rays = _RAYS.get(key)
    if rays is not None:
        return rays
    shelf = _shelves(map_key, shelves)
    beams = _beams(heading, shelf, map_key)
    inv_y = beams.inv_y
    rays = _Rays(
        beams=beams,
        shelf=shelf,
        oy=oy,
        wall_y=np.where(inv_y > 0, (HEIGHT_M - oy) * inv_y, -oy * inv_y),
        cy2=tuple((min(max(oy, b[1]), b[3]) - oy) ** 2 for b in shelf.boxes),
        by_near={},
        last=None,
    )
    # Straight driving keeps one entry for many cycles; a turn never comes back to a pose.
    if len(_RAYS) >= 16:
        del _RAYS[next(iter(_RAYS))]
    _RAYS[key] = rays
    return rays


def _table(rays: _Rays, near: tuple[bool, ...]) -> _Table:
    """The walls' rows, then those of the shelves in range."""
    rows = np.flatnonzero(near)
    n, beams = 2 + len(rows), len(rays.wall_y)
    inv_y, oy = rays.beams.inv_y, rays.oy
    y0 = rays.shelf.y0[rows] - oy
    y0 *= inv_y
    y1 = rays.shelf.y1[rows] - oy
    y1 *= inv_y
    y_in, y_out = np.empty((n, beams)), np.empty((n, beams))
    y_in[0], y_in[1], y_out[:2] = -np.inf, rays.wall_y, np.inf
    shelf_in, shelf_out = y_in[2:], y_out[2:]
    np.minimum(y0, y1, out=shelf_in)
    np.maximum(y0, y1, out=shelf_out)
    # A pair whose y-slab is behind the robot never hits (the hit needs 0 < t <= y_out); one
    # whose y-slab starts beyond the LiDAR's range can only lower a range that is beyond it
    # to another such range, and every range beyond LIDAR_RANGE_MAX reads as "no return".
    cannot = shelf_out <= 0.0
    cannot |= shelf_in > LIDAR_RANGE_MAX
    np.copyto(shelf_in, np.inf, where=cannot)
    np.copyto(shelf_out, -np.inf, where=cannot)
    x = np.empty((2, n, beams))
    x[:, :2] = rays.beams.wall_x
    x[:, 2:] = rays.beams.shelf_x[:, rows]
    return _Table(
        x=x,
        inv_x=rays.beams.inv_x,
        y_in=y_in,
        y_out=y_out,
        ahead=bool(shelf_in.min(initial=np.inf) > 0.0),
    )


def _static_ranges(rays: _Rays, ox: float, oy: float) -> np.ndarray:
    """Ranges to the map (shelves and outer walls) along each beam: the slab method.

    The array returned is shared with the next call from the same ``ox``: do not modify it.
    """
    last = rays.last
    if last is not None and last[0] == ox:
        return last[1]
    # Only shelves within range can be hit.
    near = tuple(
        (min(max(ox, box[0]), box[2]) - ox) ** 2 + cy2 < LIDAR_RANGE_MAX**2
        for box, cy2 in zip(rays.shelf.boxes, rays.cy2, strict=True)
    )
    table = rays.by_near.get(near)
    if table is None:
        table = _table(rays, near)
        rays.by_near[near] = table
    # Entering the x-slab through x_in is min(x0, x1) of the textbook slab test, exactly.
    t = table.x - ox
    t *= table.inv_x
    t_in = np.maximum(t[0], table.y_in)
    hit = np.minimum(t[1], table.y_out) >= t_in
    if not table.ahead:
        hit &= t_in > 0.0
    # ufunc reduce, not ndarray.min: the same minimum without numpy's Python-level wrapper
    best: np.ndarray = np.minimum.reduce(np.where(hit, t_in, np.inf), axis=0)
    rays.last = (ox, best)
    return best


def _local_dirs(beams: _Beams, heading: float, c: float, s: float) -> _Local:
    """Every beam's direction in the frame of a box actor with ``heading`` (c, s its cos, sin);
    actors keep their heading (pallets, a forklift on the aisle), so this is mostly cached."""
    local = beams.local.get(heading)
    if local is None:
        ldx, ldy = c * beams.dx + s * beams.dy, -s * beams.dx + c * beams.dy
        ldx = np.where(np.abs(ldx) < 1e-12, 1e-12, ldx)
        ldy = np.where(np.abs(ldy) < 1e-12, 1e-12, ldy)
        local = (ldx, ldy, ldx.tolist(), ldy.tolist())
        if len(beams.local) < 64:
            beams.local[heading] = local
    return local


_FEW_BEAMS = 20
"""Up to this many beams, a Python loop is cheaper than numpy's per-call cost."""


def _actor_ranges(
    actor: Actor, pose: tuple[float, float, float], rays: _Rays, out: np.ndarray
) -> None:
    """Lower ``out`` where beams hit ``actor`` (a circle, or an oriented box)."""
    ox, oy, heading = pose
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
    if actor.kind == "person":
        # A handful of beams.
        r = 0.5 * actor.length
        c = dist * dist - r * r
        dxs, dys = rays.beams.dx_list, rays.beams.dy_list
        for i in range(i0, i1 + 1):
            b = dxs[i] * rx + dys[i] * ry
            disc = b * b - c
            if disc >= 0.0:
                out[i] = min(out[i], b - math.sqrt(disc))
        return
    c, s = math.cos(actor.heading), math.sin(actor.heading)
    # Ray origin and direction in the actor's frame (directions cached per actor heading).
    lx, ly = -(c * rx + s * ry), -(-s * rx + c * ry)
    ldx_all, ldy_all, ldx_list, ldy_list = _local_dirs(rays.beams, actor.heading, c, s)
    hl, hw = 0.5 * actor.length, 0.5 * actor.width
    ax, bx, ay, by = -hl - lx, hl - lx, -hw - ly, hw - ly
    if i1 - i0 < _FEW_BEAMS:
        # The slab test below, beam by beam, with the same operations in the same order.
        for i in range(i0, i1 + 1):
            ldx, ldy = ldx_list[i], ldy_list[i]
            x0, x1, y0, y1 = ax / ldx, bx / ldx, ay / ldy, by / ldy
            if x0 > x1:
                x0, x1 = x1, x0
            if y0 > y1:
                y0, y1 = y1, y0
            t_in = x0 if x0 > y0 else y0
            t_out = x1 if x1 < y1 else y1
            if t_out >= t_in > 0.0:
                out[i] = min(out[i], t_in)
        return
    ldx_v, ldy_v = ldx_all[i0 : i1 + 1], ldy_all[i0 : i1 + 1]
    x0_v, x1_v = ax / ldx_v, bx / ldx_v
    y0_v, y1_v = ay / ldy_v, by / ldy_v
    tmin = np.maximum(np.minimum(x0_v, x1_v), np.minimum(y0_v, y1_v))
    tmax = np.minimum(np.maximum(x0_v, x1_v), np.maximum(y0_v, y1_v))
    hits = np.where((tmax >= tmin) & (tmin > 0.0), tmin, np.inf)
    seg = out[i0 : i1 + 1]
    np.minimum(seg, hits, out=seg)


def scan_lidar(world: World, rng: np.random.Generator) -> LidarScan:
    """Ray-cast one scan from the robot's pose, with range noise."""
    ox, oy, heading = world.robot_pose()
    rays = _rays(heading, oy, world.shelves)
    expected = _static_ranges(rays, ox, oy)
    truth = expected.copy()
    for actor in world.actors:
        _actor_ranges(actor, (ox, oy, heading), rays, truth)
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
        detections.append(CameraDetection(b, box, (scores[0], scores[1], scores[2])))
    return detections


_US_BEAMS = slice(beam_of(-US_HALF_ANGLE), beam_of(US_HALF_ANGLE) + 1)
"""The LiDAR beams inside the ultrasonic cone (its echo is the nearest surface there)."""


def range_ultrasonic(truth_ranges: np.ndarray, rng: np.random.Generator) -> float | None:
    """Nearest echo in the forward cone, or None beyond range."""
    nearest = float(np.minimum.reduce(truth_ranges[_US_BEAMS]))
    if nearest > US_RANGE_MAX:
        return None
    return max(0.02, nearest + float(rng.normal(0.0, US_NOISE_M)))
