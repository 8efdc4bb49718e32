"""How good the robot was, measured against the world's ground truth (never logged, never
read by the metrics): perception's classification per class, and each scenario's safety
outcomes.

- Classification: each entity perception reports as observed this cycle is matched to the
  nearest actor footprint within ``MATCH_M`` (none: a false detection, true class
  ``none``); the confusion matrix counts (true class, perceived class) over entity-cycles.
- Safety, per scenario: the minimum separation between the robot's footprint and any
  person's or vehicle's; near-miss cycles (a person or vehicle closer than ``NEAR_MISS_M``)
  and events (runs of such cycles); time to stop, from each STOP onset until the actual
  speed is under the monitor's stop tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from sim.execution import STOP_SPEED
from sim.perception import PerceptionOutput
from sim.policy import STOP
from sim.world import PERIOD_S, Actor, World

ROBOT_RADIUS_M = 0.3
MATCH_M = 1.0
NEAR_MISS_M = 0.5
TRUE_CLASSES = ("person", "forklift", "pallet", "none")
PERCEIVED_CLASSES = ("person", "forklift", "pallet")


def footprint_distance(actor: Actor, x: float, y: float) -> float:
    """Distance from (x, y) to the actor's footprint (0 inside)."""
    dx, dy = x - actor.x, y - actor.y
    if actor.kind == "person":
        return max(0.0, math.hypot(dx, dy) - actor.length / 2)
    c, s = math.cos(actor.heading), math.sin(actor.heading)
    ax, ay = c * dx + s * dy, -s * dx + c * dy
    ex = max(0.0, abs(ax) - actor.length / 2)
    ey = max(0.0, abs(ay) - actor.width / 2)
    return math.hypot(ex, ey)


@dataclass(slots=True)
class _Safety:
    cycles: int = 0
    min_person_m: float = math.inf
    min_vehicle_m: float = math.inf
    near_miss_cycles: int = 0
    near_miss_events: int = 0
    stops: int = 0
    stop_times_s: list[float] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        times = sorted(self.stop_times_s)
        return {
            "cycles": self.cycles,
            "min_separation_person_m": _metres(self.min_person_m),
            "min_separation_vehicle_m": _metres(self.min_vehicle_m),
            "near_miss_cycles": self.near_miss_cycles,
            "near_miss_events": self.near_miss_events,
            "stops": self.stops,
            "time_to_stop_median_s": round(times[len(times) // 2], 1) if times else None,
            "time_to_stop_max_s": round(times[-1], 1) if times else None,
        }


def _metres(value: float) -> float | None:
    return None if math.isinf(value) else round(value, 2)


class QualityMeter:
    """Accumulates classification and safety outcomes cycle by cycle."""

    def __init__(self) -> None:
        self.confusion: dict[str, dict[str, int]] = {
            t: dict.fromkeys(PERCEIVED_CLASSES, 0) for t in TRUE_CLASSES
        }
        self.safety: dict[str, _Safety] = {}
        self._near = False
        self._stop_started: float | None = None
        self._prev_command: str | None = None

    def observe(
        self, world: World, seen: PerceptionOutput, scenario: str, command: str, speed: float
    ) -> None:
        """One cycle: what perception reported, what the robot chose and its actual speed."""
        actors = world.actors
        for e in seen.entities:
            if not e.observed or e.cls not in PERCEIVED_CLASSES:
                continue
            best, best_d = "none", MATCH_M
            for a in actors:
                d = footprint_distance(a, e.x, e.y)
                if d <= best_d:
                    best, best_d = a.kind, d
            self.confusion[best][e.cls] += 1

        s = self.safety.setdefault(scenario, _Safety())
        s.cycles += 1
        x, y, _ = world.robot_pose()
        near = False
        for a in actors:
            if a.kind == "pallet":
                continue
            gap = max(0.0, footprint_distance(a, x, y) - ROBOT_RADIUS_M)
            if a.kind == "person":
                s.min_person_m = min(s.min_person_m, gap)
            else:
                s.min_vehicle_m = min(s.min_vehicle_m, gap)
            near = near or gap < NEAR_MISS_M
        if near:
            s.near_miss_cycles += 1
            if not self._near:
                s.near_miss_events += 1
        self._near = near

        if command == STOP and self._prev_command != STOP:
            s.stops += 1
            self._stop_started = world.t
        if self._stop_started is not None:
            if command != STOP:
                self._stop_started = None  # released before standing still: not timed
            elif speed <= STOP_SPEED:
                s.stop_times_s.append(world.t - self._stop_started + PERIOD_S)
                self._stop_started = None
        self._prev_command = command

    def perception(self) -> dict[str, Any]:
        """The confusion matrix with each perceived class's precision and each true class's
        recall (among what was perceived)."""
        per_class = {}
        for c in PERCEIVED_CLASSES:
            said = sum(self.confusion[t][c] for t in TRUE_CLASSES)
            true = sum(self.confusion[c].values())
            per_class[c] = {
                "precision": round(self.confusion[c][c] / said, 3) if said else None,
                "recall": round(self.confusion[c][c] / true, 3) if true else None,
            }
        return {"confusion": self.confusion, "per_class": per_class}

    def outcomes(self) -> dict[str, dict[str, Any]]:
        """Safety outcomes per scenario."""
        return {name: s.as_dict() for name, s in self.safety.items()}
