"""Layer 4: commanded motion, actuator lag and noise, and the compliance monitor.

The monitor's rules and the policy agree by construction: the policy slows before the
speed limit near people applies, and the monitor allows for the braking it can see (the
actuator's first-order lag towards a command within the limit); its stop tolerance sits
above the actuator's noise floor. With no fault injected a failed check therefore means the
robot did something wrong, not that the monitor and the policy disagree.

Motion (``Steering``, the executive under the policy): STOP, SLOW and CONTINUE keep to the
route's centre line with a lane-keeping steer bounded to ``MAX_YAW_RATE``. REROUTE is a path
change, never an instantaneous flip: the 4 m aisle leaves no room to pass a forklift or an
obstacle, so the robot turns back along the route, a U-turn at ``MAX_YAW_RATE`` (radius
0.5 m at 0.3 m/s, about 5 s) that is completed once begun (a STOP still halts it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.belief import BeliefGraph
from sim.policy import CONTINUE, REROUTE, SLOW, STOP
from sim.world import PERIOD_S

MOTION = {CONTINUE: (1.2, 0.0), SLOW: (0.3, 0.0), STOP: (0.0, 0.0), REROUTE: (0.3, 0.6)}
TAU_S = 0.25
NOISE_LINEAR = 0.02
NOISE_ANGULAR = 0.02
HALF_TRACK_M = 0.25  # converts an angular-rate error into a wheel-speed error
TURN_NOISE_FULL = 0.3
"""Speed (m/s, or rad/s commanded) from which the angular noise is at its full level."""

MAX_YAW_RATE = 0.6
"""rad/s: the turn rate of a REROUTE, and the bound on the lane-keeping steer."""
K_YAW, K_LATERAL = 1.5, 0.8
"""Lane keeping: w = -K_YAW * heading error - K_LATERAL * lateral offset (stable at 0.3 and
1.2 m/s: both closed-loop poles have real part -0.75 /s)."""

MAX_SPEED = 1.5
PERSON_ZONE_M = 3.0
PERSON_SPEED = 0.5
STOP_GRACE_S = 1.0
STOP_SPEED = 0.1
"""m/s: five standard deviations of the actuator's speed noise, so a stopped robot passes."""
ENVELOPE_SLACK = 0.1
BRAKING_SLACK = 3 * NOISE_LINEAR
"""Allowed above the lag's expected speed while braking towards a command within a limit."""


TURN_DONE_RAD = 0.15
"""A U-turn ends within this of the reversed route heading (lane keeping takes over)."""


class Steering:
    """Turns the chosen command into (linear, angular), remembering a U-turn in progress."""

    def __init__(self) -> None:
        self.turning_from: int | None = None
        """Direction of travel along the route when the U-turn in progress began."""

    def steer(
        self, command: str, *, heading_error: float, lateral: float, direction: int
    ) -> tuple[float, float]:
        """(linear, angular) for this cycle. ``heading_error`` (rad) and ``lateral`` (m, left)
        are the robot's offsets from its direction of travel along the route."""
        if (
            self.turning_from is not None
            and direction != self.turning_from
            and heading_error >= -TURN_DONE_RAD
        ):
            self.turning_from = None  # heading back along the route: the turn is done
        if command == REROUTE and self.turning_from is None:
            self.turning_from = direction
        if command == STOP:
            return 0.0, 0.0
        linear, _ = MOTION[command]
        if self.turning_from is not None:
            # A U-turn is completed once begun, at the REROUTE speed whatever the command,
            # unless a STOP halts it: half a turn would leave the robot across the aisle.
            return min(linear, MOTION[REROUTE][0]), MAX_YAW_RATE
        w = -K_YAW * heading_error - K_LATERAL * lateral
        return linear, round(max(-MAX_YAW_RATE, min(MAX_YAW_RATE, w)), 4)


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Check:
    """One compliance rule's verdict on this cycle's motion."""

    rule: str
    passed: bool
    value: float | None
    limit: float | None
    detail: str


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Executed:
    """Layer 4 for one cycle: the motion wanted, the motion measured, and the checks."""

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

    def step(
        self,
        command: str,
        t: float,
        belief: BeliefGraph,
        want: tuple[float, float] | None = None,
    ) -> Executed:
        """Apply ``command`` (as ``want`` = (linear, angular) when steered) for one period;
        measure and check the result."""
        want_v, want_w = MOTION[command] if want is None else want
        prev_v = self.linear
        prev_err = abs(want_v - self.linear)
        v, w = self._move(want_v, want_w)
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
            self._person_check(v, prev_v, want_v, _nearest_person(belief)),
        ]
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

    def _move(self, want_v: float, want_w: float) -> tuple[float, float]:
        """One period of lag and noise towards (``want_v``, ``want_w``): the new (v, w)."""
        noise = self.rng.normal(0.0, 1.0, 2).tolist()
        v = self.linear + self._alpha * (want_v - self.linear) + NOISE_LINEAR * noise[0]
        # Turning noise comes from the wheels' speed control: a robot held still on its
        # brakes does not turn (else it would drift in heading through a long STOP).
        moving = min(1.0, (abs(self.linear) + abs(want_v) + abs(want_w)) / TURN_NOISE_FULL)
        w = self.angular + self._alpha * (want_w - self.angular) + NOISE_ANGULAR * moving * noise[1]
        v = max(0.0, v)
        self.linear, self.angular = v, w
        return v, w

    def _person_check(
        self, v: float, prev_v: float, want_v: float, nearest: tuple[float, str] | None
    ) -> Check:
        """The speed limit near people, given the nearest person (distance, id) believed."""
        if nearest is None or not nearest[0] < PERSON_ZONE_M:
            return Check(
                "person_speed_limit",
                True,
                None,
                PERSON_SPEED,
                f"no person within {PERSON_ZONE_M} m",
            )
        # Braking towards a speed within the limit, at the actuator's rate, complies: the
        # limit cannot be met faster than the robot can brake.
        braking = want_v <= PERSON_SPEED and v <= (
            prev_v + self._alpha * (want_v - prev_v) + BRAKING_SLACK
        )
        detail = f"{nearest[1]} at {nearest[0]:.2f} m (< {PERSON_ZONE_M} m)"
        if v > PERSON_SPEED and braking:
            detail += f"; braking towards {want_v:.1f} m/s at the actuator's rate"
        return Check(
            "person_speed_limit",
            v <= PERSON_SPEED or braking,
            round(v, 3),
            PERSON_SPEED,
            detail,
        )


def _nearest_person(belief: BeliefGraph) -> tuple[float, str] | None:
    """(distance, id) of the nearest person the belief graph holds a distance for."""
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
    return nearest
