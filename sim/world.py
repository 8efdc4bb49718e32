"""The warehouse: a 50 m x 30 m floor with shelf rows, a looping robot route and actors.

Everything here is ground truth. The robot's pipeline (sensors -> perception -> belief ->
policy) only ever sees the world through ``sim.sensors``; nothing downstream reads an
``Actor`` directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

WIDTH_M = 50.0
HEIGHT_M = 30.0
PERIOD_S = 0.1

# Shelf rows run along x and are split by a central cross-aisle (x 24..26); the outer
# cross-aisles are x < 5 and x > 45. Aisles between rows are 4 m wide (centres y = 7, 13, 19, 25).
SHELF_ROWS_Y: tuple[tuple[float, float], ...] = (
    (3.0, 5.0),
    (9.0, 11.0),
    (15.0, 17.0),
    (21.0, 23.0),
    (27.0, 28.5),
)
SHELF_SPANS_X: tuple[tuple[float, float], ...] = ((5.0, 24.0), (26.0, 45.0))


def shelf_boxes() -> np.ndarray:
    """Static map: shelf boxes as rows of (xmin, ymin, xmax, ymax)."""
    return np.array(
        [(x0, y0, x1, y1) for (y0, y1) in SHELF_ROWS_Y for (x0, x1) in SHELF_SPANS_X],
        dtype=np.float64,
    )


# The robot shuttles along the aisle y = 7 between the west and east cross-aisles, turning
# around at each end (and whenever it reroutes). A straight route keeps "ahead" meaningful.
POSE_YAW_STEP = 0.01
POSE_LATERAL_STEP = 0.01
"""Grid of the pose the robot reports (and its sensors render from), in rad and m from the
route: a return moves by at most 2.5 mrad x range (1 cm at 4 m, the LiDAR's 1.5 cm noise)."""
LATERAL_MAX_M = 1.4
"""How far from the aisle's centre line the robot may go (4 m aisle, 0.6 m wide robot)."""
ROUTE_START = (2.5, 7.0)
ROUTE_END = (47.5, 7.0)


class Route:
    """A straight route parametrised by arc length ``s`` in [0, length]."""

    def __init__(
        self, start: tuple[float, float] = ROUTE_START, end: tuple[float, float] = ROUTE_END
    ) -> None:
        self.start = start
        self.length = math.hypot(end[0] - start[0], end[1] - start[1])
        self.direction = ((end[0] - start[0]) / self.length, (end[1] - start[1]) / self.length)

    def point(self, s: float) -> tuple[float, float]:
        """World position at arc length ``s`` (clamped to the route)."""
        s = min(self.length, max(0.0, s))
        return self.start[0] + s * self.direction[0], self.start[1] + s * self.direction[1]

    def tangent(self, s: float) -> tuple[float, float]:
        """Unit direction of increasing ``s``."""
        return self.direction

    def to_end(self, s: float, direction: int) -> float:
        """Distance left before the robot must turn around, driving in ``direction``."""
        return self.length - s if direction > 0 else s


@dataclass(slots=True)
class RobotState:
    """Ground-truth robot state. ``s`` runs along the route and ``direction`` says which way
    the robot travels along it; ``yaw`` (rad, left positive) and ``lateral`` (m, left of the
    route's increasing ``s``) are its offsets from the route's centre line. A turn past 90
    degrees reverses ``direction`` (and re-expresses ``yaw``): the heading stays continuous."""

    s: float = 0.0
    direction: int = 1
    linear: float = 0.0
    angular: float = 0.0
    last_flip_t: float = -1e9
    yaw: float = 0.0
    lateral: float = 0.0

    def offsets(self) -> tuple[float, float]:
        """(heading error, lateral offset to the left of the direction of travel)."""
        return self.yaw, self.direction * self.lateral


@dataclass(slots=True)
class Actor:
    """A person, forklift or pallet. Moves through ``legs`` of (duration_s, vx, vy)."""

    kind: str  # "person" | "forklift" | "pallet"
    x: float
    y: float
    length: float  # along heading; a person is a circle of diameter ``length``
    width: float
    heading: float = 0.0
    legs: list[tuple[float, float, float]] = field(default_factory=list)
    leg_t: float = 0.0
    brake_within_m: float = 0.0  # a driver / walker stops when this close to the robot
    path_half_width_m: float = 0.0
    """With ``brake_within_m``: brake only when the robot is this close to the actor's line
    of travel (a driver stops for a robot in the way, not for one that has given way)."""
    vx: float = 0.0
    vy: float = 0.0
    name: str = ""

    def step(self, dt: float, robot_xy: tuple[float, float]) -> None:
        """Advance by ``dt``: follow the current leg, or brake near the robot."""
        vx = vy = 0.0
        if self.legs:
            duration, vx, vy = self.legs[0]
            self.leg_t += dt
            if self.leg_t >= duration:
                self.legs.pop(0)
                self.leg_t = 0.0
        if self.brake_within_m > 0.0:
            dx, dy = robot_xy[0] - self.x, robot_xy[1] - self.y
            gap = math.hypot(dx, dy)
            in_way = True
            speed = math.hypot(vx, vy)
            if self.path_half_width_m > 0.0 and speed > 0.0:
                ahead = (dx * vx + dy * vy) / speed
                aside = abs(dx * vy - dy * vx) / speed
                in_way = ahead > 0.0 and aside < self.path_half_width_m
            if gap < self.brake_within_m and in_way:
                vx = vy = 0.0
        self.vx, self.vy = vx, vy
        self.x += vx * dt
        self.y += vy * dt


class World:
    """The warehouse, the robot on its route, and the actors of the current episode."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.route = Route()
        self.robot = RobotState(s=float(rng.uniform(0.0, 20.0)))
        self.actors: list[Actor] = []
        self.shelves = shelf_boxes()
        self.t = 0.0
        self._pose_key: tuple[float, int, float, float] | None = None
        self._pose = (0.0, 0.0, 0.0)

    # --- robot pose -----------------------------------------------------------------

    def robot_pose(self) -> tuple[float, float, float]:
        """(x, y, heading) of the robot."""
        robot = self.robot
        key = (robot.s, robot.direction, robot.yaw, robot.lateral)
        if key == self._pose_key:  # asked for several times a cycle
            return self._pose
        x, y = self.route.point(robot.s)
        tx, ty = self.route.tangent(robot.s)
        # The offsets from the route are reported on a grid (see POSE_*_STEP): the sensors'
        # ray geometry is cached per pose, and a robot driving straight stays on one.
        lateral = round(robot.lateral / POSE_LATERAL_STEP) * POSE_LATERAL_STEP
        yaw = round(robot.yaw / POSE_YAW_STEP) * POSE_YAW_STEP
        x, y = x - ty * lateral, y + tx * lateral
        if robot.direction < 0:
            tx, ty = -tx, -ty
        self._pose_key, self._pose = key, (x, y, math.atan2(ty, tx) + yaw)
        return self._pose

    def along_route(self, ahead_m: float, lateral_m: float) -> tuple[float, float, float]:
        """A point ``ahead_m`` along the robot's route and ``lateral_m`` to its left.

        Returns (x, y, heading of the route there).
        """
        s = self.robot.s + self.robot.direction * ahead_m
        x, y = self.route.point(s)
        tx, ty = self.route.tangent(s)
        if self.robot.direction < 0:
            tx, ty = -tx, -ty
        return x - ty * lateral_m, y + tx * lateral_m, math.atan2(ty, tx)

    # --- dynamics -------------------------------------------------------------------

    def apply_motion(self, linear: float, angular: float, flip: bool = False) -> None:
        """Move the robot one period with its actual (post-actuator) speeds (unicycle model).

        ``flip`` turns the robot around on the spot (tests only; the robot itself turns at
        its yaw rate)."""
        robot = self.robot
        robot.linear, robot.angular = linear, angular
        if flip:
            robot.direction = -robot.direction
            robot.last_flip_t = self.t
        robot.yaw += angular * PERIOD_S
        robot.s += robot.direction * linear * math.cos(robot.yaw) * PERIOD_S
        lateral = robot.lateral + robot.direction * linear * math.sin(robot.yaw) * PERIOD_S
        robot.lateral = max(-LATERAL_MAX_M, min(LATERAL_MAX_M, lateral))
        if abs(robot.yaw) > math.pi / 2:  # now travelling the other way along the route
            robot.direction = -robot.direction
            robot.yaw -= math.copysign(math.pi, robot.yaw)
            robot.last_flip_t = self.t
        if not 0.0 < robot.s < self.route.length:  # end of the aisle: turn around
            robot.s = min(self.route.length, max(0.0, robot.s))
            robot.direction = -robot.direction

    def make_room(self, needed_m: float) -> None:
        """Before an episode: turn around if the aisle ahead is shorter than ``needed_m``."""
        robot = self.robot
        here = self.route.to_end(robot.s, robot.direction)
        if here < needed_m and self.route.to_end(robot.s, -robot.direction) > here:
            robot.direction = -robot.direction

    def step_actors(self) -> None:
        """Advance every actor one period and the clock."""
        x, y, _ = self.robot_pose()
        for actor in self.actors:
            actor.step(PERIOD_S, (x, y))
        self.t += PERIOD_S
