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
_PREFIX = {"person": "ped", "forklift": "forklift", "pallet": "obj"}
# LiDAR width likelihood per class: mean, std of the visible extent (m).
_WIDTH_MODEL = {"person": (0.45, 0.15), "forklift": (1.9, 0.6), "pallet": (1.1, 0.35)}
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


@dataclass(slots=True)
class Track:
    id: str
    logp: list[float]  # log class posterior, in CLASSES order
    x: float
    y: float
    vx: float = 0.0
    vy: float = 0.0
    width: float = 0.5
    hits: int = 1
    missed: int = 0
    evidence: list[EvidenceItem] = field(default_factory=list)
    observed: bool = True

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
    clusters: list[Cluster] = []
    n = len(idx)
    start = 0
    for k in range(1, n + 1):
        # A cluster is a run of adjacent beams without a range jump.
        if k < n and idx[k] - idx[k - 1] <= 1 and abs(rs[k] - rs[k - 1]) < CLUSTER_JUMP_M:
            continue
        if k - start >= MIN_CLUSTER_BEAMS:
            first, last = idx[start], idx[k - 1]
            r = rs[start:k]
            xs = [ri * ci for ri, ci in zip(r, _COS[first : last + 1], strict=True)]
            ys = [ri * si for ri, si in zip(r, _SIN[first : last + 1], strict=True)]
            width = math.hypot(xs[-1] - xs[0], ys[-1] - ys[0])
            cx, cy = sum(xs) / len(xs), sum(ys) / len(ys)
            clusters.append(
                Cluster(
                    index=len(clusters),
                    first=first,
                    last=last,
                    ranges=[round(v, 3) for v in r],
                    x=cx,
                    y=cy,
                    width=width,
                    bearing=math.atan2(cy, cx),
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


_WIDTH_TERMS = [(mu, sd, math.log(sd)) for mu, sd in _WIDTH_MODEL.values()]


def _width_loglik(width: float) -> list[float]:
    return [-0.5 * ((width - mu) / sd) ** 2 - log_sd for mu, sd, log_sd in _WIDTH_TERMS]


def _score_loglik(scores: tuple[float, ...]) -> list[float]:
    return [math.log(s + 0.05) for s in scores]


def _normalize(logp: list[float]) -> list[float]:
    m = max(logp)
    z = m + math.log(sum(math.exp(v - m) for v in logp))
    return [v - z for v in logp]


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
        fg: list[int] = []
        fg_ranges: list[float] = []
        if scan is not None:
            fg_idx = np.flatnonzero(scan.ranges < scan.expected - FOREGROUND_MARGIN_M)
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
            ll = _width_loglik(c.width)
            det_i = det_of_cluster.get(c.index)
            seen_by: CameraDetection | None = None  # the camera detection fused in, if any
            if det_i is not None and detections is not None:
                seen_by = detections[det_i]
            if seen_by is not None:
                ll = [a + b for a, b in zip(ll, _score_loglik(seen_by.scores), strict=True)]
            known = track_of.get(c.index)
            if known is None:
                logp = _normalize(ll)
                top = _argmax(logp)
                # Name by class only when the first look is fairly sure; ids never change.
                cls = CLASSES[top] if math.exp(logp[top]) >= 0.6 else "pallet"
                t = Track(self._new_id(cls), logp, wx, wy, width=c.width)
                self.tracks.append(t)
            else:
                t = known
                ax, ay = wx - t.x, wy - t.y
                t.x += 0.5 * ax
                t.y += 0.5 * ay
                t.vx = max(-3.0, min(3.0, t.vx + 0.25 * ax / PERIOD_S))
                t.vy = max(-3.0, min(3.0, t.vy + 0.25 * ay / PERIOD_S))
                t.width = 0.7 * t.width + 0.3 * c.width
                moving = math.hypot(t.vx, t.vy) > 0.4
                if moving:  # pallets do not move
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
