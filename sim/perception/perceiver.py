"""Layer 1 per cycle: the ``Perceiver`` that keeps the tracks and reports entities.

One ``step``: cluster the LiDAR's foreground returns, match clusters and camera detections
to tracks, log the readings used, update the tracks, and report every entity with the
evidence it rests on and the free corridor ahead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.perception.association import (
    detections_of_clusters,
    detections_of_tracks,
    tracks_of_clusters,
)
from sim.perception.classes import look_loglik
from sim.perception.clusters import Cluster, clusters_of, foreground
from sim.perception.corridor import CorridorView, corridor_returns, remembered_view, seen_view
from sim.perception.evidence import FUSED_WEIGHTS, EvidenceItem, LogSensor, SensorRefs
from sim.perception.frames import Pose, to_world
from sim.perception.sensor_log import log_camera, log_lidar, log_ultrasonic
from sim.perception.tracks import (
    MAX_COAST_CYCLES,
    Track,
    age,
    follow_bearing,
    follow_look,
    predict,
    start_track,
    view_rate,
)
from sim.sensors import US_HALF_ANGLE, CameraDetection, LidarScan

__all__ = ["PerceivedEntity", "Perceiver", "PerceptionOutput"]

_PREFIX = {"person": "ped", "forklift": "forklift", "pallet": "obj"}
_US_HALF_ANGLE_4 = round(US_HALF_ANGLE, 4)


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
class PerceptionOutput:
    """One cycle of layer 1: the entities, the corridor, and which sensors were up."""

    entities: tuple[PerceivedEntity, ...]
    corridor: CorridorView
    sensors_used: tuple[str, ...]
    sensors_unavailable: tuple[str, ...]


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
        pose: Pose,
        speed: float,
        scan: LidarScan | None,
        detections: list[CameraDetection] | None,
        us_range: float | None,
        corridor_length: float,
        log_sensor: LogSensor,
    ) -> PerceptionOutput:
        """Run layer 1 for one cycle; readings it uses are logged through ``log_sensor``."""
        self._tick += 1
        fg, fg_ranges = foreground(scan) if scan is not None else ([], [])
        clusters = clusters_of(fg, fg_ranges)
        predict(self.tracks)
        world_c = [to_world(c.x, c.y, pose) for c in clusters]
        track_of = tracks_of_clusters(self.tracks, clusters, world_c)
        matches = self._match_detections(clusters, detections, lidar=scan is not None, pose=pose)
        returns = corridor_returns(fg, fg_ranges, corridor_length) if scan is not None else []
        lidar_ref = (
            None if scan is None else log_lidar(log_sensor, clusters, corridor_length, returns)
        )
        camera_ref = None if detections is None else log_camera(log_sensor, detections)
        refs = SensorRefs(lidar_ref, camera_ref, log_ultrasonic(log_sensor, us_range))

        self._update_tracks(
            clusters, world_c, track_of, detections, matches, pose=pose,
            speed=speed, us_range=us_range, refs=refs, cycle=cycle,
        )  # fmt: skip
        if scan is None:
            corridor = remembered_view(
                self._corridor, speed, length=corridor_length, refs=refs, us_range=us_range,
                cycle=cycle,
            )  # fmt: skip
        else:
            corridor = seen_view(
                clusters, track_of, returns, length=corridor_length, refs=refs, us_range=us_range,
                cycle=cycle,
            )  # fmt: skip
        self._corridor = corridor
        return _output(self.tracks, corridor, lidar=scan is not None, camera=detections is not None)

    def _match_detections(
        self,
        clusters: list[Cluster],
        detections: list[CameraDetection] | None,
        *,
        lidar: bool,
        pose: Pose,
    ) -> tuple[dict[int, int], dict[int, int]]:
        """Camera detections matched to clusters (by index) or, LiDAR down, to tracks."""
        if not detections:
            return {}, {}
        if lidar:
            return detections_of_clusters(clusters, detections), {}
        return {}, detections_of_tracks(self.tracks, detections, pose)

    def _update_tracks(
        self,
        clusters: list[Cluster],
        world_c: list[tuple[float, float]],
        track_of: dict[int, Track],
        detections: list[CameraDetection] | None,
        matches: tuple[dict[int, int], dict[int, int]],
        *,
        pose: Pose,
        speed: float,
        us_range: float | None,
        refs: SensorRefs,
        cycle: int,
    ) -> None:
        """Every track updated from this cycle's looks, then aged; ``track_of`` learns the
        tracks started for clusters no track continued."""
        det_of_cluster, det_of_track = matches
        for c in clusters:
            det_i = det_of_cluster.get(c.index)
            seen_by = None if det_i is None or detections is None else detections[det_i]
            self._follow_cluster(c, world_c[c.index], seen_by, track_of, speed)
            track_of[c.index].evidence = _cluster_evidence(c, seen_by, us_range, refs, cycle)
        if detections is not None:
            for ti, di in det_of_track.items():
                follow_bearing(self.tracks[ti], detections[di], pose, refs.camera, cycle)
        self.tracks = age(self.tracks, self._tick)

    def _follow_cluster(
        self,
        c: Cluster,
        world: tuple[float, float],
        seen_by: CameraDetection | None,
        track_of: dict[int, Track],
        speed: float,
    ) -> None:
        """Update the track cluster ``c`` continues, or start one (``track_of`` learns it)."""
        ll = look_loglik(c, seen_by)
        look = (self._tick, world[0], world[1], c.width, view_rate(c.x, c.y, speed))
        known = track_of.get(c.index)
        if known is None:
            t = start_track(self._new_id, c, world, ll, look)
            self.tracks.append(t)
            # The corridor must know whose returns these are from the first look: a
            # person seen for the first time is not an obstacle that blocks the aisle.
            track_of[c.index] = t
        else:
            t = known
            follow_look(t, c, world, ll, look)
        t.observed = True


def _cluster_evidence(
    c: Cluster,
    seen_by: CameraDetection | None,
    us_range: float | None,
    refs: SensorRefs,
    cycle: int,
) -> list[EvidenceItem]:
    """What a cluster's entity rests on: its beams, the fused camera box, the echo if any."""
    in_cone = abs(math.atan2(c.y, c.x)) <= US_HALF_ANGLE
    echo = us_range is not None and in_cone and abs(min(c.ranges) - us_range) < 0.4
    w = FUSED_WEIGHTS[seen_by is not None, echo]
    evidence = [
        EvidenceItem("lidar", w[0], "beams", (float(c.first), float(c.last)), refs.lidar, cycle)
    ]
    if seen_by is not None:
        evidence.append(EvidenceItem("camera", w[1], "pixels", seen_by.box, refs.camera, cycle))
    if echo:
        assert us_range is not None
        cone = (0.0, _US_HALF_ANGLE_4, round(us_range, 3))
        evidence.append(EvidenceItem("ultrasonic", w[-1], "cone", cone, refs.ultrasonic, cycle))
    return evidence


def _output(
    tracks: list[Track], corridor: CorridorView, *, lidar: bool, camera: bool
) -> PerceptionOutput:
    """The entities worth reporting (seen lately, with evidence) and the sensors' state."""
    entities = tuple(
        PerceivedEntity(
            t.id, t.cls(), t.confidence(), t.x, t.y, t.vx, t.vy, t.observed, tuple(t.evidence)
        )
        for t in tracks
        if t.missed <= MAX_COAST_CYCLES and t.evidence
    )
    status = (("lidar", lidar), ("camera", camera))
    used = [s for s, ok in status if ok] + ["ultrasonic"]
    down = [s for s, ok in status if not ok]
    return PerceptionOutput(entities, corridor, tuple(used), tuple(down))
