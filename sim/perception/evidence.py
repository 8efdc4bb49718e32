"""What an entity rests on: evidence items, their weights by sensor, and how they fade.

Each item names a region of one logged sensor message (LiDAR beams, camera pixels, the
ultrasonic cone) through the ref the logger returned for that message.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["FUSED_WEIGHTS", "EvidenceItem", "LogSensor", "Ref", "SensorRefs", "coasting"]

Ref = Any
"""An evidence ref as returned by the logger (opaque to perception)."""
LogSensor = Callable[[str, dict[str, Any]], Ref]

_SENSOR_WEIGHT = {"lidar": 0.6, "camera": 0.3, "ultrasonic": 0.1}


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


@dataclass(frozen=True, slots=True)
class SensorRefs:
    """The refs of one cycle's logged sensor messages; ``None`` for a sensor that is down."""

    lidar: Ref
    camera: Ref
    ultrasonic: Ref


def _weights(sensors: list[str], scale: float = 1.0) -> list[float]:
    total = sum(_SENSOR_WEIGHT[s] for s in sensors)
    return [round(scale * _SENSOR_WEIGHT[s] / total, 3) for s in sensors]


FUSED_WEIGHTS = {
    (camera, echo): _weights(["lidar"] + ["camera"] * camera + ["ultrasonic"] * echo)
    for camera in (False, True)
    for echo in (False, True)
}
"""Evidence weights of a LiDAR cluster, by whether the camera and the ultrasonic back it."""


def coasting(e: EvidenceItem) -> EvidenceItem:
    """``e`` a cycle older and unconfirmed: it still supports what it did, at half weight."""
    return EvidenceItem(
        e.sensor, round(e.weight * 0.5, 3), e.region_kind, e.region_values, e.ref, e.cycle
    )
