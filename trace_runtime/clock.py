"""The clock rules: when a robot's clock went back between two stretches of its log, and which
clocks tell the time of day.

Within a session a robot's time never goes back (the logger refuses a cycle begun earlier than
the previous one), but PROFILE section 4 lets a new session start on a clock that restarted:
a segment whose first time is earlier than the time its predecessor in the chain ended. Equal
times are not a restart (a segment rotated mid-session may begin at the instant the last one
ended); they are one run. ``Log.clock_runs`` splits a log's runs with it, ``verify`` notes it,
and ``metrics`` starts a fresh continuity window after it, so the three always agree.
A writer whose clock steps back mid-session (chrony, a ROS time source reset) begins a segment
that declares the step (``trace.session`` ``clock_step_from_ns``); ``Log.clock_steps`` lists
every such boundary as a ``ClockStep``, declared or not.

A segment's ``clock`` names the clock behind its times (PROFILE section 3). Only a wall clock
(``system``: nanoseconds since the Unix epoch) gives a time of day: times of such a log are
shown and accepted as ISO 8601 UTC, and the fleet index partitions its rows by UTC day. A
``sim`` or ``monotonic`` clock counts from an arbitrary zero; its times stay seconds. So does
a ``system`` log whose times start before 2000 (``EARLIEST_WALL_NS``): a reader assumes
``system`` when a writer named no clock, and a log counting from zero is not a time of day.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass

__all__ = [
    "EARLIEST_WALL_NS",
    "WALL_CLOCKS",
    "ClockStep",
    "clock_restarted",
    "is_wall_clock",
    "iso_utc",
    "offset_hint",
    "show_instant",
    "show_time",
]

WALL_CLOCKS = frozenset({"system"})
"""Clock names whose ``t_ns`` are nanoseconds since the Unix epoch (UTC)."""
EARLIEST_WALL_NS = 946_684_800 * 1_000_000_000
"""2000-01-01T00:00:00Z: a wall-clock log starts after it."""


@dataclass(frozen=True, slots=True)
class ClockStep:
    """Where a robot's clock went back between two of its segments: from ``from_ns`` (the
    last time before it) to ``to_ns`` (the first time of ``segment``, which begins at
    ``first_cycle``). ``declared``: its writer declared the step in that segment's
    ``trace.session`` (a clock stepped back mid-session, the chain and cycles going on);
    else the robot restarted on a clock that begins lower."""

    robot_id: str
    segment: str
    segment_no: int
    first_cycle: int
    from_ns: int
    to_ns: int
    declared: bool

    @property
    def back_ns(self) -> int:
        """How far the clock went back."""
        return self.from_ns - self.to_ns


def clock_restarted(before_ns: int, after_ns: int) -> bool:
    """True when a stretch starting at ``after_ns`` follows one that ended at ``before_ns`` on a
    clock that went back."""
    return after_ns < before_ns


def is_wall_clock(clock: str, start_ns: int) -> bool:
    """True when times of a log on ``clock`` starting at ``start_ns`` are times of day
    (nanoseconds since the Unix epoch, UTC)."""
    return clock in WALL_CLOCKS and start_ns >= EARLIEST_WALL_NS


_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.UTC)


def iso_utc(t_ns: int, *, digits: int = 9) -> str:
    """A wall-clock time as ISO 8601 UTC with ``digits`` decimals of the second (trailing
    zeros dropped when ``digits`` is 9, so the text is exact but short)."""
    whole, part = divmod(t_ns, 1_000_000_000)
    moment = (_EPOCH + _dt.timedelta(seconds=whole)).strftime("%Y-%m-%dT%H:%M:%S")
    fraction = f"{part:09d}"[:digits]
    if digits == 9:
        fraction = fraction.rstrip("0")
    return f"{moment}.{fraction}Z" if fraction else f"{moment}Z"


def show_time(t_ns: int, clock: str, start_ns: int) -> str:
    """A time of a log on ``clock`` that starts at ``start_ns``, as people read it, to the
    millisecond: ``2026-05-04T06:04:25.900Z (+265.000 s)`` on a wall clock, else
    ``265.000 s``."""
    if not is_wall_clock(clock, start_ns):
        return f"{t_ns / 1e9:.3f} s"
    return f"{iso_utc(t_ns, digits=3)} ({(t_ns - start_ns) / 1e9:+.3f} s)"


def offset_hint(clock: str, start_ns: int, *times_ns: int | None) -> str:
    """What to say after a time on a wall clock that fell in 1970: a plain number there is
    seconds since the epoch, and ``+S`` (seconds after the log's start, ``log_time``) is
    what was meant. ``""`` on any other clock, or when no time is that early (a time of day
    that misses the log is simply outside it)."""
    if not is_wall_clock(clock, start_ns):
        return ""
    early = [t for t in times_ns if t is not None and 0 <= t < EARLIEST_WALL_NS]
    if not early:
        return ""
    return (
        f"; on this wall clock a plain number is seconds since 1970: "
        f"+{early[0] / 1e9:g} counts from the log's start"
    )


def show_instant(t_ns: int, clock: str) -> str:
    """One time of a log on ``clock`` on its own (in a message): ISO 8601 UTC to the
    millisecond when it is a time of day, else seconds."""
    return iso_utc(t_ns, digits=3) if is_wall_clock(clock, t_ns) else f"{t_ns / 1e9:.3f} s"
