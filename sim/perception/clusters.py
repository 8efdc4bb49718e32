"""Which LiDAR returns belong together: foreground returns grouped into clusters.

A return is foreground when it is nearer than the map predicts; a cluster is a run of
adjacent foreground beams without a range jump, with its centroid, visible extent and
whether an edge of it is hidden.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.sensors import BEAM_ANGLES, LIDAR_BEAMS, LidarScan

__all__ = [
    "CLUSTER_JUMP_M",
    "FOREGROUND_MARGIN_M",
    "MIN_CLUSTER_BEAMS",
    "Cluster",
    "cluster_scan",
    "clusters_of",
    "foreground",
]

FOREGROUND_MARGIN_M = 0.3
CLUSTER_JUMP_M = 0.3
MIN_CLUSTER_BEAMS = 2

_COS = np.cos(BEAM_ANGLES).tolist()
_SIN = np.sin(BEAM_ANGLES).tolist()


@dataclass(slots=True)
class Cluster:
    """A run of adjacent foreground beams ``first..last``, in the robot frame."""

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


def foreground(scan: LidarScan) -> tuple[list[int], list[float]]:
    """The beams whose return is nearer than the map predicts (ascending), and their ranges."""
    fg = (scan.ranges < scan.expected - FOREGROUND_MARGIN_M).nonzero()[0]
    return fg.tolist(), scan.ranges[fg].tolist()


def cluster_scan(scan: LidarScan) -> list[Cluster]:
    """Group foreground returns (closer than the map predicts) into clusters."""
    return clusters_of(*foreground(scan))


def clusters_of(idx: list[int], rs: list[float]) -> list[Cluster]:
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
