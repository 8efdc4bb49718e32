"""Layer 4: commanded motion, actuator lag and noise, and the compliance monitor."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.belief import BeliefGraph
from sim.policy import CONTINUE, REROUTE, SLOW, STOP

PERIOD_S = 0.1
MOTION = {CONTINUE: (1.2, 0.0), SLOW: (0.3, 0.0), STOP: (0.0, 0.0), REROUTE: (0.3, 0.6)}
TAU_S = 0.25
NOISE_LINEAR = 0.02
NOISE_ANGULAR = 0.02
HALF_TRACK_M = 0.25  # converts an angular-rate error into a wheel-speed error

MAX_SPEED = 1.5
PERSON_ZONE_M = 3.0
PERSON_SPEED = 0.5
STOP_GRACE_S = 1.0
STOP_SPEED = 0.05
ENVELOPE_SLACK = 0.1


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Check:
    rule: str
    passed: bool
    value: float | None
    limit: float | None
    detail: str


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Executed:
    intended: tuple[float, float]
    actual: tuple[float, float]
    deviation: float
    checks: tuple[Check, ...]


class Actuator:
    """First-order lag (time constant TAU_S) with Gaussian noise on both axes."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.linear = 0.0
        self.angular = 0.0
        self._alpha = 1.0 - math.exp(-PERIOD_S / TAU_S)
        self._stop_since: float | None = None

    def step(self, command: str, t: float, belief: BeliefGraph) -> Executed:
        """Apply ``command`` for one period; measure and check the result."""
        want_v, want_w = MOTION[command]
        prev_err = abs(want_v - self.linear)
        noise = self.rng.normal(0.0, 1.0, 2)
        v = self.linear + self._alpha * (want_v - self.linear) + NOISE_LINEAR * float(noise[0])
        w = self.angular + self._alpha * (want_w - self.angular) + NOISE_ANGULAR * float(noise[1])
        v = max(0.0, v)
        self.linear, self.angular = v, w
        dev = math.hypot(want_v - v, HALF_TRACK_M * (want_w - w))

        if command == STOP:
            if self._stop_since is None:
                self._stop_since = t
        else:
            self._stop_since = None
        checks = [
            Check(
                "max_speed",
                v <= MAX_SPEED,
                round(v, 3),
                MAX_SPEED,
                f"actual linear speed {v:.2f} m/s",
            ),
        ]
        nearest: tuple[float, str] | None = None
        people = [n.id for n in belief.nodes if n.kind == "entity" and n.value == "person"]
        if people:
            by_id = {m.id: m for m in belief.nodes}  # node ids are unique
            for pid in people:
                m = by_id.get(f"{pid}.distance")
                if (
                    m is not None
                    and isinstance(m.value, float)
                    and (nearest is None or m.value < nearest[0])
                ):
                    nearest = (m.value, pid)
        if nearest is not None and nearest[0] < PERSON_ZONE_M:
            checks.append(
                Check(
                    "person_speed_limit",
                    v <= PERSON_SPEED,
                    round(v, 3),
                    PERSON_SPEED,
                    f"{nearest[1]} at {nearest[0]:.2f} m (< {PERSON_ZONE_M} m)",
                )
            )
        else:
            checks.append(
                Check(
                    "person_speed_limit",
                    True,
                    None,
                    PERSON_SPEED,
                    f"no person within {PERSON_ZONE_M} m",
                )
            )
        if self._stop_since is not None and t - self._stop_since >= STOP_GRACE_S:
            checks.append(
                Check(
                    "stop_response",
                    v <= STOP_SPEED,
                    round(v, 3),
                    STOP_SPEED,
                    f"STOP held {t - self._stop_since:.1f} s",
                )
            )
        envelope = prev_err * (1.0 - self._alpha) + ENVELOPE_SLACK
        checks.append(
            Check(
                "command_tracking",
                abs(want_v - v) <= envelope,
                round(abs(want_v - v), 3),
                round(envelope, 3),
                "speed error within the actuator's lag envelope",
            )
        )
        return Executed((want_v, want_w), (round(v, 4), round(w, 4)), round(dev, 4), tuple(checks))
