"""Which look is whose: LiDAR clusters to tracks, camera detections to clusters or tracks.

Clusters go to the nearest predicted track within a gate (greedy, nearest pairs first); a
camera detection goes to the cluster whose beams span its bearing (the closest in bearing
first), or, when the LiDAR is down, to the first track whose bearing it matches.
"""

from __future__ import annotations

import math

from sim.perception.clusters import Cluster
from sim.perception.frames import Pose, to_robot
from sim.perception.tracks import Track
from sim.sensors import LIDAR_ANGLE_INC, LIDAR_ANGLE_MIN, CameraDetection

__all__ = ["detections_of_clusters", "detections_of_tracks", "tracks_of_clusters"]

_BEARING_SLACK = math.radians(1.5)


def tracks_of_clusters(
    tracks: list[Track], clusters: list[Cluster], world_c: list[tuple[float, float]]
) -> dict[int, Track]:
    """The track each cluster (by index; world centroids ``world_c``) continues, if any."""
    pairs = []
    for ti, t in enumerate(tracks):
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
        track_of[ci] = tracks[ti]
    return track_of


def detections_of_clusters(
    clusters: list[Cluster], detections: list[CameraDetection]
) -> dict[int, int]:
    """The camera detection (by index) fused into each cluster (by index), if any."""
    det_of_cluster: dict[int, int] = {}
    taken: set[int] = set()
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
    return det_of_cluster


def detections_of_tracks(
    tracks: list[Track], detections: list[CameraDetection], pose: Pose
) -> dict[int, int]:
    """The camera detection (by index) that updates each track (by index), LiDAR down."""
    det_of_track: dict[int, int] = {}
    taken: set[int] = set()
    for ti, t in enumerate(tracks):
        rx, ry = to_robot(t.x, t.y, pose)
        b, r = math.atan2(ry, rx), math.hypot(rx, ry)
        tol = math.radians(3.0) + math.atan2(0.5 * t.width, max(r, 0.1))
        for di, det in enumerate(detections):
            if di not in taken and abs(det.bearing - b) < tol:
                taken.add(di)
                det_of_track[ti] = di
                break
    return det_of_track
