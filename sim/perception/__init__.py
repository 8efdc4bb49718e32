"""Layer 1: LiDAR clustering, tracking and camera fusion into evidence-grounded entities.

The pipeline per cycle (``Perceiver.step``): foreground LiDAR returns (those in front of the
map) are grouped into clusters (``clusters``); clusters are associated with tracks, camera
detections with clusters by bearing (``association``); each track's class posterior is
updated from the cluster's width, its motion and the detector's scores (``classes``,
``tracks``); the free corridor ahead is measured (``corridor``). Every entity carries the
evidence it rests on (``evidence``): the LiDAR cluster (beam range), the camera box and the
ultrasonic cone, each with the ref of the ``/sensors/...`` message that holds exactly those
returns (``sensor_log``).
"""

from __future__ import annotations

from sim.perception.clusters import Cluster, cluster_scan
from sim.perception.corridor import CORRIDOR_HALF_WIDTH_M, CORRIDOR_MAX_M, CorridorView
from sim.perception.evidence import EvidenceItem, LogSensor, Ref
from sim.perception.perceiver import PerceivedEntity, Perceiver, PerceptionOutput
from sim.perception.sensor_log import TOPIC_CAMERA, TOPIC_LIDAR, TOPIC_ULTRASONIC
from sim.perception.tracks import VELOCITY_MIN_LOOKS, Track

__all__ = [
    "CORRIDOR_HALF_WIDTH_M",
    "CORRIDOR_MAX_M",
    "TOPIC_CAMERA",
    "TOPIC_LIDAR",
    "TOPIC_ULTRASONIC",
    "VELOCITY_MIN_LOOKS",
    "Cluster",
    "CorridorView",
    "EvidenceItem",
    "LogSensor",
    "PerceivedEntity",
    "Perceiver",
    "PerceptionOutput",
    "Ref",
    "Track",
    "cluster_scan",
]
