"""The robot frame and the world frame: a point seen from a pose, and back."""

from __future__ import annotations

import math

__all__ = ["Pose", "to_robot", "to_world"]

Pose = tuple[float, float, float]
"""The robot's x, y (m, world frame) and heading (rad)."""


def to_robot(x: float, y: float, pose: Pose) -> tuple[float, float]:
    """World point (x, y) in the robot frame of ``pose``."""
    ox, oy, h = pose
    c, s = math.cos(h), math.sin(h)
    dx, dy = x - ox, y - oy
    return c * dx + s * dy, -s * dx + c * dy


def to_world(x: float, y: float, pose: Pose) -> tuple[float, float]:
    """Robot-frame point (x, y) of ``pose`` in the world frame."""
    ox, oy, h = pose
    c, s = math.cos(h), math.sin(h)
    return ox + c * x - s * y, oy + s * x + c * y
