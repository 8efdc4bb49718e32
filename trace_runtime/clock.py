"""The clock rules: when a robot's clock went back between two stretches of its log, and which
clocks tell the time of day.

Within a session a robot's time never goes back (the logger refuses a cycle begun earlier than
the previous one), but PROFILE section 4 lets a new session start on a clock that restarted:
a segment whose first time is earlier than the time its predecessor in the chain ended. Equal
times are not a restart (a segment rotated mid-session may begin at the instant the last one
ended); they are one run. ``Log.clock_runs`` splits a log's runs with it, ``verify`` notes it,
and ``metrics`` starts a fresh continuity window after it, so the three always agree.

A segment's ``clock`` names the clock behind its times (PROFILE section 3). Only a wall clock
(``system``: nanoseconds since the Unix epoch) gives a time of day: times of such a log are
shown and accepted as ISO 8601 UTC, and the fleet index partitions its rows by UTC day. A
``sim`` or ``monotonic`` clock counts from an arbitrary zero; its times stay seconds. So does
a ``system`` log whose times start before 2000 (``EARLIEST_WALL_NS``): a reader assumes
``system`` when a writer named no clock, and a log counting from zero is not a time of day.
"""

from __future__ import annotations

__all__ = ["EARLIEST_WALL_NS", "WALL_CLOCKS", "clock_restarted", "is_wall_clock"]

WALL_CLOCKS = frozenset({"system"})
"""Clock names whose ``t_ns`` are nanoseconds since the Unix epoch (UTC)."""
EARLIEST_WALL_NS = 946_684_800 * 1_000_000_000
"""2000-01-01T00:00:00Z: a wall-clock log starts after it."""


def clock_restarted(before_ns: int, after_ns: int) -> bool:
    """True when a stretch starting at ``after_ns`` follows one that ended at ``before_ns`` on a
    clock that went back."""
    return after_ns < before_ns


def is_wall_clock(clock: str, start_ns: int) -> bool:
    """True when times of a log on ``clock`` starting at ``start_ns`` are times of day
    (nanoseconds since the Unix epoch, UTC)."""
    return clock in WALL_CLOCKS and start_ns >= EARLIEST_WALL_NS
