"""Layer 1: LiDAR clustering, tracking and camera fusion into evidence-grounded entities.

The pipeline per cycle: foreground LiDAR returns (those in front of the map) are grouped
into clusters; clusters are associated with tracks; camera detections are associated with
clusters by bearing; each track's class posterior is updated from the cluster's width, its
motion and the detector's scores. Every entity carries the evidence it rests on: the LiDAR
cluster (beam range), the camera box and the ultrasonic cone, each with the ref of the
``/sensors/...`` message that holds exactly those returns.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim.sensors import (
    BEAM_ANGLES,
    CAMERA_HALF_FOV,
    CLASSES,
    IMAGE_H,
    IMAGE_W,
    LIDAR_ANGLE_INC,
    LIDAR_ANGLE_MIN,
    LIDAR_BEAMS,
    LIDAR_RANGE_MAX,
    US_HALF_ANGLE,
    US_RANGE_MAX,
    CameraDetection,
    LidarScan,
)

TOPIC_LIDAR = "/sensors/lidar"
TOPIC_CAMERA = "/sensors/camera"
TOPIC_ULTRASONIC = "/sensors/ultrasonic"

PERIOD_S = 0.1
FOREGROUND_MARGIN_M = 0.3
CLUSTER_JUMP_M = 0.3
MIN_CLUSTER_BEAMS = 2
CORRIDOR_HALF_WIDTH_M = 0.8
CORRIDOR_MAX_M = 10.0
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
_PREFIX = {"person": "ped", "forklift": "forklift", "pallet": "obj"}
# LiDAR extent per class: the visible extent (first to last return, m) lies anywhere in
# [low, high], measured with Gaussian error sd. A person (0.5 m across) shows 0.15-0.5 m
# (fewer beams far away); a pallet (1.2 x 1.0 m) one face or two, up to its 1.56 m diagonal;
# a forklift (2.4 x 1.2 m) its 1.2 m front up to its 2.7 m diagonal. Between 0.9 and 1.6 m
# the LiDAR cannot tell a pallet from a forklift, so it gives "forklift" no support there
# (a pallet's narrower range makes it the likelier of the two); only the camera can.
_EXTENT_MODEL = {
    "person": (0.15, 0.5, 0.08),
    "forklift": (0.9, 2.7, 0.1),
    "pallet": (0.9, 1.6, 0.1),
}
_PRIOR = {"person": 0.3, "forklift": 0.1, "pallet": 0.6}
"""What a new track is before its first look says otherwise: in a warehouse aisle most things
are goods; it also settles looks that say nothing (a sliver of a half-hidden pallet)."""
_LOG_PRIOR = [math.log(_PRIOR[c]) for c in CLASSES]
_SENSOR_WEIGHT = {"lidar": 0.6, "camera": 0.3, "ultrasonic": 0.1}

Ref = Any
"""An evidence ref as returned by the logger (opaque to perception)."""
LogSensor = Callable[[str, dict[str, Any]], Ref]


# Hot per-cycle value types are plain slotted dataclasses, not frozen ones: a frozen
# dataclass's __init__ costs ~4x as much, and nothing here mutates them after creation.


@dataclass(slots=True)
class EvidenceItem:
    """One member of an evidence set: where, how much, and the logged reading it names."""

    sensor: str
    weight: float
    region_kind: str
    region_values: tuple[float, ...]
    ref: Ref
    cycle: int  # the cycle whose sensor message the ref names


@dataclass(slots=True)
class Cluster:
    index: int
    first: int
    last: int
    ranges: list[float]
    x: float  # robot frame
    y: float
    width: float
    bearing: float
    truncated: bool = False
    """An edge is hidden (a nearer return beside it, or the edge of the scan): only part of
    the object is in view, so ``width`` is a lower bound and the centroid is not its own."""


@dataclass(slots=True)
class Track:
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
    looks: list[tuple[int, float, float, float, float]] = field(default_factory=list)
    """Recent LiDAR looks: (tick, centroid x, centroid y, visible extent, view-angle rate)."""
    motion: str = "unknown"
    """``unknown`` (too few looks), ``static`` or ``moving``."""

    def confidence(self) -> dict[str, float]:
        m = max(self.logp)
        p = [math.exp(v - m) for v in self.logp]
        total = sum(p)
        return {
            c: round(min(0.999, max(0.001, v / total)), 4) for c, v in zip(CLASSES, p, strict=True)
        }

    def cls(self) -> str:
        return CLASSES[_argmax(self.logp)]


@dataclass(slots=True)
class PerceivedEntity:
    """A tracked object as layer 1 reports it (world frame)."""

    id: str
    cls: str
    confidence: dict[str, float]
    x: float
    y: float
    vx: float
    vy: float
    observed: bool
    evidence: tuple[EvidenceItem, ...]


@dataclass(frozen=True, slots=True)
class CorridorView:
    """The free corridor ahead along the route, as LiDAR (or, coasting, memory) saw it."""

    clearance: float
    length: float
    blocker: str | None  # entity id of the obstacle that bounds the clearance
    evidence: tuple[EvidenceItem, ...]


@dataclass(frozen=True, slots=True)
class PerceptionOutput:
    entities: tuple[PerceivedEntity, ...]
    corridor: CorridorView
    sensors_used: tuple[str, ...]
    sensors_unavailable: tuple[str, ...]


def _to_robot(x: float, y: float, pose: tuple[float, float, float]) -> tuple[float, float]:
    ox, oy, h = pose
    c, s = math.cos(h), math.sin(h)
    dx, dy = x - ox, y - oy
    return c * dx + s * dy, -s * dx + c * dy


def _to_world(x: float, y: float, pose: tuple[float, float, float]) -> tuple[float, float]:
    ox, oy, h = pose
    c, s = math.cos(h), math.sin(h)
    return ox + c * x - s * y, oy + s * x + c * y


_COS = np.cos(BEAM_ANGLES).tolist()
_SIN = np.sin(BEAM_ANGLES).tolist()
_BEAM_COS = [math.cos(a) for a in BEAM_ANGLES.tolist()]
_BEAM_SIN = [math.sin(a) for a in BEAM_ANGLES.tolist()]
_HALF_CORRIDOR_ANGLE = math.atan2(CORRIDOR_HALF_WIDTH_M, 0.5)
_CORRIDOR_BEAMS = (
    max(0, math.ceil((-_HALF_CORRIDOR_ANGLE - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC)),
    min(LIDAR_BEAMS - 1, math.floor((_HALF_CORRIDOR_ANGLE - LIDAR_ANGLE_MIN) / LIDAR_ANGLE_INC)),
)
"""First and last beam that can see into the corridor strip."""
_BEARING_SLACK = math.radians(1.5)
_LIDAR_HEADER = {
    "frame": "base_link",
    "angle_min": round(LIDAR_ANGLE_MIN, 6),
    "angle_increment": round(LIDAR_ANGLE_INC, 6),
    "beams": LIDAR_BEAMS,
    "range_max": LIDAR_RANGE_MAX,
    "foreground_margin": FOREGROUND_MARGIN_M,
}
_CAMERA_HEADER = {
    "frame": "camera",
    "width": IMAGE_W,
    "height": IMAGE_H,
    "hfov": round(2 * CAMERA_HALF_FOV, 6),
    "classes": list(CLASSES),
}
_US_HEADER = {
    "frame": "base_link",
    "half_angle": round(US_HALF_ANGLE, 6),
    "range_max": US_RANGE_MAX,
}


def cluster_scan(scan: LidarScan) -> list[Cluster]:
    """Group foreground returns (closer than the map predicts) into clusters."""
    fg = np.flatnonzero(scan.ranges < scan.expected - FOREGROUND_MARGIN_M)
    return _clusters(fg.tolist(), scan.ranges[fg].tolist())


def _clusters(idx: list[int], rs: list[float]) -> list[Cluster]:
    """Clusters of the foreground beams ``idx`` (ascending) with ranges ``rs``."""
    n = len(idx)
    if n < MIN_CLUSTER_BEAMS:
        return []
    # A cluster is a run of adjacent beams without a range jump: find where runs end.
    ends = [
        k
        for k, (i0, i1, r0, r1) in enumerate(zip(idx, idx[1:], rs, rs[1:], strict=False), start=1)
        if i1 - i0 > 1 or not abs(r1 - r0) < CLUSTER_JUMP_M
    ]
    ends.append(n)
    clusters: list[Cluster] = []
    start = 0
    for k in ends:
        if k - start >= MIN_CLUSTER_BEAMS:
            first, last = idx[start], idx[k - 1]
            r = rs[start:k]
            xs = [ri * ci for ri, ci in zip(r, _COS[first : last + 1], strict=True)]
            ys = [ri * si for ri, si in zip(r, _SIN[first : last + 1], strict=True)]
            width = math.hypot(xs[-1] - xs[0], ys[-1] - ys[0])
            cx, cy = sum(xs) / len(xs), sum(ys) / len(ys)
            # Hidden edge: a nearer return on the very next beam, or the end of the scan.
            truncated = (
                first == 0
                or last == LIDAR_BEAMS - 1
                or (start > 0 and idx[start - 1] == first - 1 and rs[start - 1] < rs[start])
                or (k < n and idx[k] == last + 1 and rs[k] < rs[k - 1])
            )
            clusters.append(
                Cluster(
                    len(clusters),
                    first,
                    last,
                    [round(v, 3) for v in r],
                    cx,
                    cy,
                    width,
                    math.atan2(cy, cx),
                    truncated,
                )
            )
        start = k
    return clusters


# The class posterior has three entries: plain floats and ``math`` are several times faster
# than numpy at this size, and do not depend on which SIMD code numpy picks for exp and log.


def _argmax(values: list[float]) -> int:
    """Index of the first largest value."""
    best = 0
    for i in range(1, len(values)):
        if values[i] > values[best]:
            best = i
    return best


_EXTENT_TERMS = [_EXTENT_MODEL[c] for c in CLASSES]
_SQRT2 = math.sqrt(2.0)
_SQRT2PI = math.sqrt(2.0 * math.pi)


def _phi_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / _SQRT2)


def _width_loglik(width: float) -> list[float]:
    """log p(width | class): a uniform extent on [low, high] seen with Gaussian error."""
    return [
        math.log(
            max(1e-12, (_phi_cdf((hi - width) / sd) - _phi_cdf((lo - width) / sd)) / (hi - lo))
        )
        for lo, hi, sd in _EXTENT_TERMS
    ]


def _width_at_least_loglik(width: float) -> list[float]:
    """log P(extent >= width | class): all a partly hidden cluster's width can say."""
    out = []
    for lo, hi, sd in _EXTENT_TERMS:
        # The mean over the uniform extent of P(error > width - extent), in closed form.
        a, b = (hi - width) / sd, (lo - width) / sd
        g_a = a * _phi_cdf(a) + math.exp(-0.5 * a * a) / _SQRT2PI
        g_b = b * _phi_cdf(b) + math.exp(-0.5 * b * b) / _SQRT2PI
        out.append(math.log(max(1e-12, sd * (g_a - g_b) / (hi - lo))))
    return out


def _score_loglik(scores: tuple[float, ...]) -> list[float]:
    return [math.log(s + 0.05) for s in scores]


def _normalize(logp: list[float]) -> list[float]:
    m = max(logp)
    z = m + math.log(sum(math.exp(v - m) for v in logp))
    return [v - z for v in logp]


def _view_rate(rx: float, ry: float, speed: float) -> float:
    """|d bearing / dt| (rad/s) of a standing object at (rx, ry) as the robot drives past."""
    r2 = max(rx * rx + ry * ry, 0.25)
    return speed * abs(ry) / r2


def _update_motion(t: Track, tick: int) -> None:
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
    # Two passes instead of seven: each sum adds the same terms in the same order from the
    # same int 0 that sum() starts from, and max() keeps the first of equals as this does.
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


def _weights(sensors: list[str], scale: float = 1.0) -> list[float]:
    total = sum(_SENSOR_WEIGHT[s] for s in sensors)
    return [round(scale * _SENSOR_WEIGHT[s] / total, 3) for s in sensors]


_FUSED_WEIGHTS = {
    (camera, echo): _weights(["lidar"] + ["camera"] * camera + ["ultrasonic"] * echo)
    for camera in (False, True)
    for echo in (False, True)
}
"""Evidence weights of a LiDAR cluster, by whether the camera and the ultrasonic back it."""
_US_HALF_ANGLE_4 = round(US_HALF_ANGLE, 4)


class Perceiver:
    """Stateful layer 1: tracks persist across cycles; entity ids are stable per track."""

    def __init__(self) -> None:
        self.tracks: list[Track] = []
        self._counters: dict[str, int] = {}
        self._corridor: CorridorView | None = None
        self._tick = 0

    def forget_cycle(self, cycle: int) -> None:
        """The cycle's sensor messages never reached the log: stop pointing at them."""
        for t in self.tracks:
            t.evidence = [e for e in t.evidence if e.cycle != cycle]
        if self._corridor is not None:
            ev = tuple(e for e in self._corridor.evidence if e.cycle != cycle)
            self._corridor = CorridorView(
                self._corridor.clearance, self._corridor.length, self._corridor.blocker, ev
            )

    def _new_id(self, cls: str) -> str:
        prefix = _PREFIX[cls]
        n = self._counters.get(prefix, 0) + 1
        self._counters[prefix] = n
        return f"{prefix}_{n}"

    def step(
        self,
        *,
        cycle: int,
        pose: tuple[float, float, float],
        speed: float,
        scan: LidarScan | None,
        detections: list[CameraDetection] | None,
        us_range: float | None,
        corridor_length: float,
        log_sensor: LogSensor,
    ) -> PerceptionOutput:
        """Run layer 1 for one cycle; readings it uses are logged through ``log_sensor``."""
        self._tick += 1
        tick = self._tick
        fg: list[int] = []
        fg_ranges: list[float] = []
        if scan is not None:
            fg_idx = (scan.ranges < scan.expected - FOREGROUND_MARGIN_M).nonzero()[0]
            fg, fg_ranges = fg_idx.tolist(), scan.ranges[fg_idx].tolist()
        clusters = _clusters(fg, fg_ranges)

        # --- predict and associate clusters with tracks (greedy nearest neighbour) ------
        for t in self.tracks:
            t.x += t.vx * PERIOD_S
            t.y += t.vy * PERIOD_S
            t.observed = False
        world_c = [_to_world(c.x, c.y, pose) for c in clusters]
        pairs = []
        for ti, t in enumerate(self.tracks):
            for ci, (wx, wy) in enumerate(world_c):
                d = math.hypot(wx - t.x, wy - t.y)
                if d < 1.0 + 0.5 * max(t.width, clusters[ci].width):
                    pairs.append((d, ti, ci))
        pairs.sort()
        track_of: dict[int, Track] = {}
        used_t: set[int] = set()
        for _, ti, ci in pairs:
            if ti in used_t or ci in track_of:
                continue
            used_t.add(ti)
            track_of[ci] = self.tracks[ti]

        # --- camera detections to clusters (or, without LiDAR, to tracks) by bearing ----
        det_of_cluster: dict[int, int] = {}
        det_of_track: dict[int, int] = {}
        if detections:
            taken: set[int] = set()
            if scan is not None:
                for c in clusters:
                    lo = LIDAR_ANGLE_MIN + c.first * LIDAR_ANGLE_INC - _BEARING_SLACK
                    hi = LIDAR_ANGLE_MIN + c.last * LIDAR_ANGLE_INC + _BEARING_SLACK
                    best = None
                    for di, det in enumerate(detections):
                        if di not in taken and lo <= det.bearing <= hi:
                            err = abs(det.bearing - c.bearing)
                            if best is None or err < best[0]:
                                best = (err, di)
                    if best is not None:
                        taken.add(best[1])
                        det_of_cluster[c.index] = best[1]
            else:
                for ti, t in enumerate(self.tracks):
                    rx, ry = _to_robot(t.x, t.y, pose)
                    b, r = math.atan2(ry, rx), math.hypot(rx, ry)
                    tol = math.radians(3.0) + math.atan2(0.5 * t.width, max(r, 0.1))
                    for di, det in enumerate(detections):
                        if di not in taken and abs(det.bearing - b) < tol:
                            taken.add(di)
                            det_of_track[ti] = di
                            break

        # --- log the readings used, compactly ----------------------------------------
        lidar_ref = camera_ref = None
        corridor_returns: list[tuple[int, float]] = []
        if scan is not None:
            # Corridor: foreground returns inside the strip ahead of the robot.
            for i, r in zip(fg, fg_ranges, strict=True):
                if _CORRIDOR_BEAMS[0] <= i <= _CORRIDOR_BEAMS[1]:
                    x, y = r * _BEAM_COS[i], r * _BEAM_SIN[i]
                    if 0.0 < x <= corridor_length and abs(y) <= CORRIDOR_HALF_WIDTH_M:
                        corridor_returns.append((i, round(r, 3)))
            lidar_ref = log_sensor(
                TOPIC_LIDAR,
                {
                    **_LIDAR_HEADER,
                    "clusters": [
                        {"id": c.index, "first": c.first, "last": c.last, "ranges": c.ranges}
                        for c in clusters
                    ],
                    "corridor": {
                        "box": [
                            0.0,
                            -CORRIDOR_HALF_WIDTH_M,
                            round(corridor_length, 3),
                            CORRIDOR_HALF_WIDTH_M,
                        ],
                        "returns": corridor_returns,
                    },
                },
            )
        if detections is not None:
            camera_ref = log_sensor(
                TOPIC_CAMERA,
                {
                    **_CAMERA_HEADER,
                    "detections": [
                        {
                            "id": i,
                            "bearing": round(d.bearing, 4),
                            "box": [round(v, 1) for v in d.box],
                            "scores": [round(s, 4) for s in d.scores],
                        }
                        for i, d in enumerate(detections)
                    ],
                },
            )
        us_ref = log_sensor(
            TOPIC_ULTRASONIC,
            {**_US_HEADER, "range": None if us_range is None else round(us_range, 3)},
        )

        # --- update tracks ------------------------------------------------------------
        for c in clusters:
            wx, wy = world_c[c.index]
            ll = _width_at_least_loglik(c.width) if c.truncated else _width_loglik(c.width)
            det_i = det_of_cluster.get(c.index)
            seen_by: CameraDetection | None = None  # the camera detection fused in, if any
            if det_i is not None and detections is not None:
                seen_by = detections[det_i]
            if seen_by is not None:
                ll = [a + b for a, b in zip(ll, _score_loglik(seen_by.scores), strict=True)]
            known = track_of.get(c.index)
            look = (tick, wx, wy, c.width, _view_rate(c.x, c.y, speed))
            if known is None:
                logp = _normalize([a + b for a, b in zip(_LOG_PRIOR, ll, strict=True)])
                top = _argmax(logp)
                # Name by class only when the first look is fairly sure; ids never change.
                cls = CLASSES[top] if math.exp(logp[top]) >= 0.6 else "pallet"
                looks = [] if c.truncated else [look]
                t = Track(self._new_id(cls), logp, wx, wy, width=c.width, looks=looks)
                self.tracks.append(t)
                # The corridor must know whose returns these are from the first look: a
                # person seen for the first time is not an obstacle that blocks the aisle.
                track_of[c.index] = t
            else:
                t = known
                t.x += 0.5 * (wx - t.x)
                t.y += 0.5 * (wy - t.y)
                if not c.truncated:  # a partial view's centroid slides as the view changes
                    t.looks.append(look)
                _update_motion(t, tick)
                t.width = 0.7 * t.width + 0.3 * c.width
                # Pallets do not move: only confirmed motion says so, never a young track's
                # guess or a centroid sliding round the object as the robot passes it.
                if math.hypot(t.vx, t.vy) > MOVING_MPS:
                    ll[2] += -2.0
                t.logp = _normalize([0.8 * a + b for a, b in zip(t.logp, ll, strict=True)])
                t.hits += 1
                t.missed = 0
            t.observed = True
            in_cone = abs(math.atan2(c.y, c.x)) <= US_HALF_ANGLE
            echo = us_range is not None and in_cone and abs(min(c.ranges) - us_range) < 0.4
            w = _FUSED_WEIGHTS[seen_by is not None, echo]
            evidence = [
                EvidenceItem(
                    "lidar", w[0], "beams", (float(c.first), float(c.last)), lidar_ref, cycle
                )
            ]
            if seen_by is not None:
                evidence.append(
                    EvidenceItem("camera", w[1], "pixels", seen_by.box, camera_ref, cycle)
                )
            if echo:
                assert us_range is not None
                cone = (0.0, _US_HALF_ANGLE_4, round(us_range, 3))
                evidence.append(EvidenceItem("ultrasonic", w[-1], "cone", cone, us_ref, cycle))
            t.evidence = evidence
        if scan is None:
            for ti, di in det_of_track.items():
                t = self.tracks[ti]
                assert detections is not None
                det = detections[di]
                ll = _score_loglik(det.scores)
                t.logp = _normalize([0.8 * a + b for a, b in zip(t.logp, ll, strict=True)])
                t.observed = True
                t.missed = 0
                # Bearing-only: keep the predicted range, rotate onto the measured bearing.
                rx, ry = _to_robot(t.x, t.y, pose)
                r = math.hypot(rx, ry)
                t.x, t.y = _to_world(r * math.cos(det.bearing), r * math.sin(det.bearing), pose)
                t.evidence = [EvidenceItem("camera", 1.0, "pixels", det.box, camera_ref, cycle)]

        for t in self.tracks:
            if not t.looks or t.looks[-1][0] != tick:
                _update_motion(t, tick)  # no LiDAR look this cycle: older looks age out
            if not t.observed:
                t.missed += 1
                # Coasting: the last observation still supports the track, at half weight.
                t.evidence = [
                    EvidenceItem(
                        e.sensor,
                        round(e.weight * 0.5, 3),
                        e.region_kind,
                        e.region_values,
                        e.ref,
                        e.cycle,
                    )
                    for e in t.evidence
                ]
        self.tracks = [t for t in self.tracks if t.missed < DELETE_AFTER_MISSES]

        entities = []
        for t in self.tracks:
            if t.missed > MAX_COAST_CYCLES or not t.evidence:
                continue
            entities.append(
                PerceivedEntity(
                    t.id,
                    t.cls(),
                    t.confidence(),
                    t.x,
                    t.y,
                    t.vx,
                    t.vy,
                    t.observed,
                    tuple(t.evidence),
                )
            )

        corridor = self._corridor_view(
            cycle=cycle,
            speed=speed,
            scan=scan,
            clusters=clusters,
            track_of=track_of,
            returns=corridor_returns,
            length=corridor_length,
            lidar_ref=lidar_ref,
            us_range=us_range,
            us_ref=us_ref,
        )
        used = [
            s for s, ok in (("lidar", scan is not None), ("camera", detections is not None)) if ok
        ] + ["ultrasonic"]
        down = [
            s
            for s, ok in (("lidar", scan is not None), ("camera", detections is not None))
            if not ok
        ]
        return PerceptionOutput(tuple(entities), corridor, tuple(used), tuple(down))

    def _corridor_view(
        self,
        *,
        cycle: int,
        speed: float,
        scan: LidarScan | None,
        clusters: list[Cluster],
        track_of: dict[int, Track],
        returns: list[tuple[int, float]],
        length: float,
        lidar_ref: Ref,
        us_range: float | None,
        us_ref: Ref,
    ) -> CorridorView:
        us_ev = EvidenceItem(
            "ultrasonic",
            0.0,
            "cone",
            (
                0.0,
                round(US_HALF_ANGLE, 4),
                round(us_range if us_range is not None else US_RANGE_MAX, 3),
            ),
            us_ref,
            cycle,
        )
        if scan is None:
            prev = self._corridor
            if prev is None:
                ev: tuple[EvidenceItem, ...] = (
                    EvidenceItem(
                        "ultrasonic", 1.0, us_ev.region_kind, us_ev.region_values, us_ref, cycle
                    ),
                )
                view = CorridorView(CORRIDOR_MAX_M, length, None, ev)
            else:
                kept = [e for e in prev.evidence if e.sensor == "lidar"]
                ev_list = [
                    EvidenceItem(
                        e.sensor,
                        round(e.weight * 0.5, 3),
                        e.region_kind,
                        e.region_values,
                        e.ref,
                        e.cycle,
                    )
                    for e in kept
                ]
                ev_list.append(
                    EvidenceItem(
                        "ultrasonic", 0.2, us_ev.region_kind, us_ev.region_values, us_ref, cycle
                    )
                )
                clearance = max(0.0, prev.clearance - speed * PERIOD_S)
                view = CorridorView(min(clearance, length), length, prev.blocker, tuple(ev_list))
            self._corridor = view
            return view
        # Which tracked class does each corridor return belong to? People are excluded:
        # they are handled by the pedestrian rules and walk away; obstacles block.
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
        seen_ev = (
            EvidenceItem(
                "lidar",
                0.8,
                "box",
                (0.0, -CORRIDOR_HALF_WIDTH_M, round(length, 3), CORRIDOR_HALF_WIDTH_M),
                lidar_ref,
                cycle,
            ),
            EvidenceItem("ultrasonic", 0.2, us_ev.region_kind, us_ev.region_values, us_ref, cycle),
        )
        view = CorridorView(clearance, length, blocker, seen_ev)
        self._corridor = view
        return view
