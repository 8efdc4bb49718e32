"""What of each reading is logged: the compact ``/sensors/...`` messages evidence refs name.

The LiDAR message holds the clusters' returns and the corridor's, not the whole scan; the
camera message the detections; the ultrasonic message its one range. Each message is logged
through the ``log_sensor`` callback, and its ref is what evidence items point at.
"""

from __future__ import annotations

from sim.perception.clusters import FOREGROUND_MARGIN_M, Cluster
from sim.perception.corridor import corridor_box
from sim.perception.evidence import LogSensor, Ref
from sim.sensors import (
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
)

__all__ = [
    "TOPIC_CAMERA",
    "TOPIC_LIDAR",
    "TOPIC_ULTRASONIC",
    "log_camera",
    "log_lidar",
    "log_ultrasonic",
]

TOPIC_LIDAR = "/sensors/lidar"
TOPIC_CAMERA = "/sensors/camera"
TOPIC_ULTRASONIC = "/sensors/ultrasonic"

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


def log_lidar(
    log_sensor: LogSensor,
    clusters: list[Cluster],
    corridor_length: float,
    corridor_returns: list[tuple[int, float]],
) -> Ref:
    """Log the clusters' returns and the corridor strip's; return the message's ref."""
    return log_sensor(
        TOPIC_LIDAR,
        {
            **_LIDAR_HEADER,
            "clusters": [
                {"id": c.index, "first": c.first, "last": c.last, "ranges": c.ranges}
                for c in clusters
            ],
            "corridor": {"box": list(corridor_box(corridor_length)), "returns": corridor_returns},
        },
    )


def log_camera(log_sensor: LogSensor, detections: list[CameraDetection]) -> Ref:
    """Log the camera's detections; return the message's ref."""
    return log_sensor(
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


def log_ultrasonic(log_sensor: LogSensor, us_range: float | None) -> Ref:
    """Log the ultrasonic range (``None``: no echo); return the message's ref."""
    return log_sensor(
        TOPIC_ULTRASONIC,
        {**_US_HEADER, "range": None if us_range is None else round(us_range, 3)},
    )
