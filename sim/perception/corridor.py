"""How far the aisle ahead is free: the corridor strip, its returns, and the view of it.

With LiDAR, the clearance is the nearest foreground return in the strip ahead that is not a
person's (people are the pedestrian rules' concern and walk away; obstacles block). Without
LiDAR, the last view is remembered, shortened by the distance driven, on fading evidence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.perception.clusters import Cluster
from sim.perception.evidence import EvidenceItem, SensorRefs, coasting
from sim.perception.tracks import Track
from sim.sensors import (
    BEAM_ANGLES,
    LIDAR_ANGLE_INC,
    LIDAR_ANGLE_MIN,
    LIDAR_BEAMS,
    US_HALF_ANGLE,
    US_RANGE_MAX,
)
from sim.world import PERIOD_S

__all__ = [
    "CORRIDOR_HALF_WIDTH_M",
    "CORRIDOR_MAX_M",
    "CorridorView",
    "corridor_box",
    "corridor_returns",
    "remembered_view",
    "seen_view",
]

CORRIDOR_HALF_WIDTH_M = 0.8
CORRIDOR_MAX_M = 10.0

_BEAM_COS = [math.cos(a) for a in BEAM_ANGLES.tolist()]
_BEAM_SIN = [math.sin(a) for a in BEAM_ANGLES.tolist()]
_HALF_CORRIDOR_ANGLE = math.atan2(CORRIDOR_HALF_WIDTH_M, 0.5)
_CORRIDOR_BEAMS = (
    max(0, math.ceil((-_HALF_CORRIDOR_ANGLE - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC)),
    min(LIDAR_BEAMS - 1, math.floor((_HALF_CORRIDOR_ANGLE - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC)),
)
"""First and last beam that can see into the corridor strip."""


@dataclass(frozen=True, slots=True)
class CorridorView:
    """The free corridor ahead along the route, as LiDAR (or, coasting, memory) saw it."""

    clearance: float
    length: float
    blocker: str | None  # entity id of the obstacle that bounds the clearance
    evidence: tuple[EvidenceItem, ...]


def corridor_box(length: float) -> tuple[float, float, float, float]:
    """The strip ahead of the robot (robot frame: x0, y0, x1, y1), ``length`` m long."""
    return (0.0, -CORRIDOR_HALF_WIDTH_M, round(length, 3), CORRIDOR_HALF_WIDTH_M)


def corridor_returns(
    fg: list[int], fg_ranges: list[float], length: float
) -> list[tuple[int, float]]:
    """The foreground returns (beam, range) inside the strip ahead of the robot."""
    returns: list[tuple[int, float]] = []
    for i, r in zip(fg, fg_ranges, strict=True):
        if _CORRIDOR_BEAMS[0] <= i <= _CORRIDOR_BEAMS[1]:
            x, y = r * _BEAM_COS[i], r * _BEAM_SIN[i]
            if 0.0 < x <= length and abs(y) <= CORRIDOR_HALF_WIDTH_M:
                returns.append((i, round(r, 3)))
    return returns


def _cone(us_range: float | None) -> tuple[float, float, float]:
    reach = us_range if us_range is not None else US_RANGE_MAX
    return (0.0, round(US_HALF_ANGLE, 4), round(reach, 3))


def seen_view(
    clusters: list[Cluster],
    track_of: dict[int, Track],
    returns: list[tuple[int, float]],
    *,
    length: float,
    refs: SensorRefs,
    us_range: float | None,
    cycle: int,
) -> CorridorView:
    """The corridor as this cycle's LiDAR returns ``returns`` bound it."""
    clearance, blocker = _nearest_obstacle(clusters, track_of, returns)
    evidence = (
        EvidenceItem("lidar", 0.8, "box", corridor_box(length), refs.lidar, cycle),
        EvidenceItem("ultrasonic", 0.2, "cone", _cone(us_range), refs.ultrasonic, cycle),
    )
    return CorridorView(clearance, length, blocker, evidence)


def _nearest_obstacle(
    clusters: list[Cluster], track_of: dict[int, Track], returns: list[tuple[int, float]]
) -> tuple[float, str | None]:
    """The distance to the nearest return that is not a person's, and whose it is."""
    spans = []
    for c in clusters:
        t = track_of.get(c.index)
        spans.append((c.first, c.last, t, t is not None and t.cls() == "person"))
    clearance, blocker = CORRIDOR_MAX_M, None
    for i, r in returns:
        owner_t, person = None, False
        for first, last, t, is_person in spans:
            if first <= i <= last:
                owner_t, person = t, is_person
                break
        if person:
            continue
        x = r * _BEAM_COS[i]
        if x < clearance:
            clearance, blocker = x, (owner_t.id if owner_t is not None else None)
    return clearance, blocker


def remembered_view(
    prev: CorridorView | None,
    speed: float,
    *,
    length: float,
    refs: SensorRefs,
    us_range: float | None,
    cycle: int,
) -> CorridorView:
    """The corridor without LiDAR: the last view, shortened by the distance driven since."""
    cone = _cone(us_range)
    if prev is None:
        only = EvidenceItem("ultrasonic", 1.0, "cone", cone, refs.ultrasonic, cycle)
        return CorridorView(CORRIDOR_MAX_M, length, None, (only,))
    evidence = [coasting(e) for e in prev.evidence if e.sensor == "lidar"]
    evidence.append(EvidenceItem("ultrasonic", 0.2, "cone", cone, refs.ultrasonic, cycle))
    clearance = max(0.0, prev.clearance - speed * PERIOD_S)
    return CorridorView(min(clearance, length), length, prev.blocker, tuple(evidence))
