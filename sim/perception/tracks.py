"""Where each tracked object is and whether it moves: tracks, their motion, and their updates.

A track is predicted forward each cycle, then updated from the LiDAR cluster it was matched
with (or, without LiDAR, from a camera bearing); unmatched tracks coast on fading evidence
and are dropped after ``DELETE_AFTER_MISSES`` cycles unseen.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from sim.perception.classes import LOG_PRIOR, argmax, normalize, score_loglik
from sim.perception.clusters import Cluster
from sim.perception.evidence import EvidenceItem, Ref, coasting
from sim.perception.frames import Pose, to_robot, to_world
from sim.sensors import CLASSES, CameraDetection
from sim.world import PERIOD_S

__all__ = [
    "DELETE_AFTER_MISSES",
    "MAX_COAST_CYCLES",
    "MOTION_FLOOR_MPS",
    "MOVING_MPS",
    "VELOCITY_MIN_LOOKS",
    "VELOCITY_WINDOW_CYCLES",
    "VIEW_DRIFT_PER_RAD",
    "Look",
    "Track",
    "age",
    "follow_bearing",
    "follow_look",
    "predict",
    "start_track",
    "update_motion",
    "view_rate",
]

MAX_COAST_CYCLES = 2
DELETE_AFTER_MISSES = 4
# Track velocity: the least-squares slope of the LiDAR centroids seen in the last second. A
# younger (or just re-acquired) track has too few looks to tell motion from noise: its
# velocity is unknown, and unknown is reported as standing still, never as moving.
VELOCITY_WINDOW_CYCLES = 10
VELOCITY_MIN_LOOKS = 5
MOTION_FLOOR_MPS = 0.2
VIEW_DRIFT_PER_RAD = 0.5
"""How far the centroid of the visible surface slides, per radian of change in the angle it
is seen from, as a fraction of the visible extent. Sweeping the view of a box by 90 degrees
moves it from one face centre to the next (0.32 x the diagonal per radian); 0.5 x the
extent leaves a margin for the coarse beam sampling of near objects."""
MOVING_MPS = 0.4
"""Confirmed motion at least this fast counts against the pallet class."""
_FIRST_LOOK_SURE = 0.6
"""A new track is named by its class only when its first look is this sure; ids never
change, so a doubtful first look is named as the commonest thing in an aisle."""

Look = tuple[int, float, float, float, float]
"""One LiDAR look: (tick, centroid x, centroid y, visible extent, view-angle rate)."""


@dataclass(slots=True)
class Track:
    """One object followed across cycles (world frame), with its class posterior."""

    id: str
    logp: list[float]  # log class posterior, in CLASSES order
    x: float
    y: float
    vx: float = 0.0
    vy: float = 0.0
    """Confirmed velocity (world frame); zero while unknown or explained by the view."""
    width: float = 0.5
    hits: int = 1
    missed: int = 0
    evidence: list[EvidenceItem] = field(default_factory=list)
    observed: bool = True
    looks: list[Look] = field(default_factory=list)
    """Recent LiDAR looks, oldest first."""
    motion: str = "unknown"
    """``unknown`` (too few looks), ``static`` or ``moving``."""

    def confidence(self) -> dict[str, float]:
        """The class posterior as probabilities, clipped to [0.001, 0.999]."""
        m = max(self.logp)
        p = [math.exp(v - m) for v in self.logp]
        total = sum(p)
        return {
            c: round(min(0.999, max(0.001, v / total)), 4) for c, v in zip(CLASSES, p, strict=True)
        }

    def cls(self) -> str:
        """The likeliest class."""
        return CLASSES[argmax(self.logp)]


def predict(tracks: list[Track]) -> None:
    """Move each track one period along its velocity; none is observed yet this cycle."""
    for t in tracks:
        t.x += t.vx * PERIOD_S
        t.y += t.vy * PERIOD_S
        t.observed = False


def view_rate(rx: float, ry: float, speed: float) -> float:
    """|d bearing / dt| (rad/s) of a standing object at (rx, ry) as the robot drives past."""
    r2 = max(rx * rx + ry * ry, 0.25)
    return speed * abs(ry) / r2


def update_motion(t: Track, tick: int) -> None:
    """Re-estimate ``t``'s velocity from its recent looks; see ``VELOCITY_WINDOW_CYCLES``.

    The centroid of the returns is that of the surface in view, not of the object: driving
    past a pallet, the robot sees its front, then its side, and the centroid slides along
    with the robot. A slide no faster than the change of view can explain
    (``VIEW_DRIFT_PER_RAD`` x extent x view-angle rate) is no evidence of motion. An object on
    a collision course keeps a constant bearing, so its motion is never explained away.
    """
    looks = [k for k in t.looks if tick - k[0] < VELOCITY_WINDOW_CYCLES]
    t.looks = looks
    n = len(looks)
    if n < VELOCITY_MIN_LOOKS:
        t.motion, t.vx, t.vy = "unknown", 0.0, 0.0
        return
    # Two passes over the looks: each sum adds the same terms in the same order from the
    # same int 0 that sum() starts from, and max() keeps the first of equals as this does,
    # so the figures are those of the plain sum() and max() formulas, bit for bit.
    st: float = 0  # an int 0, as sum() starts from
    sx: float = 0
    sy: float = 0
    for k in looks:
        st += k[0]
        sx += k[1]
        sy += k[2]
    tm, xm, ym = st / n, sx / n, sy / n
    stt: float = 0
    sxt: float = 0
    syt: float = 0
    first = looks[0]
    extent, rate = first[3], first[4]
    for k in looks:
        dt = k[0] - tm
        stt += dt**2
        sxt += dt * (k[1] - xm)
        syt += dt * (k[2] - ym)
        extent = max(extent, k[3])
        rate = max(rate, k[4])
    stt *= PERIOD_S
    vx, vy = sxt / stt, syt / stt
    if math.hypot(vx, vy) <= MOTION_FLOOR_MPS + VIEW_DRIFT_PER_RAD * extent * rate:
        t.motion, t.vx, t.vy = "static", 0.0, 0.0
        return
    t.motion, t.vx, t.vy = "moving", max(-3.0, min(3.0, vx)), max(-3.0, min(3.0, vy))


def start_track(
    new_id: Callable[[str], str],
    c: Cluster,
    world: tuple[float, float],
    ll: list[float],
    look: Look,
) -> Track:
    """A track for cluster ``c`` seen for the first time at ``world``, named by ``new_id``."""
    logp = normalize([a + b for a, b in zip(LOG_PRIOR, ll, strict=True)])
    top = argmax(logp)
    cls = CLASSES[top] if math.exp(logp[top]) >= _FIRST_LOOK_SURE else "pallet"
    looks = [] if c.truncated else [look]
    return Track(new_id(cls), logp, world[0], world[1], width=c.width, looks=looks)


def follow_look(
    t: Track, c: Cluster, world: tuple[float, float], ll: list[float], look: Look
) -> None:
    """Update ``t`` from its matched cluster ``c`` at ``world`` with look likelihood ``ll``."""
    wx, wy = world
    t.x += 0.5 * (wx - t.x)
    t.y += 0.5 * (wy - t.y)
    if not c.truncated:  # a partial view's centroid slides as the view changes
        t.looks.append(look)
    update_motion(t, look[0])
    t.width = 0.7 * t.width + 0.3 * c.width
    # Pallets do not move: only confirmed motion says so, never a young track's
    # guess or a centroid sliding round the object as the robot passes it.
    if math.hypot(t.vx, t.vy) > MOVING_MPS:
        ll[2] += -2.0
    t.logp = normalize([0.8 * a + b for a, b in zip(t.logp, ll, strict=True)])
    t.hits += 1
    t.missed = 0


def follow_bearing(t: Track, det: CameraDetection, pose: Pose, camera_ref: Ref, cycle: int) -> None:
    """Update ``t`` from a camera detection alone (no LiDAR this cycle)."""
    ll = score_loglik(det.scores)
    t.logp = normalize([0.8 * a + b for a, b in zip(t.logp, ll, strict=True)])
    t.observed = True
    t.missed = 0
    # Bearing-only: keep the predicted range, rotate onto the measured bearing.
    rx, ry = to_robot(t.x, t.y, pose)
    r = math.hypot(rx, ry)
    t.x, t.y = to_world(r * math.cos(det.bearing), r * math.sin(det.bearing), pose)
    t.evidence = [EvidenceItem("camera", 1.0, "pixels", det.box, camera_ref, cycle)]


def age(tracks: list[Track], tick: int) -> list[Track]:
    """The end of a cycle: looks age out, unseen tracks coast, long-lost ones are dropped."""
    for t in tracks:
        if not t.looks or t.looks[-1][0] != tick:
            update_motion(t, tick)  # no LiDAR look this cycle: older looks age out
        if not t.observed:
            t.missed += 1
            t.evidence = [coasting(e) for e in t.evidence]
    return [t for t in tracks if t.missed < DELETE_AFTER_MISSES]
