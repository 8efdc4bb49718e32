"""The one clock-restart rule: when a robot's clock went back between two stretches of its log.

Within a session a robot's time never goes back (the logger refuses a cycle begun earlier than
the previous one), but PROFILE section 4 lets a new session start on a clock that restarted:
a segment whose first time is earlier than the time its predecessor in the chain ended. Equal
times are not a restart (a segment rotated mid-session may begin at the instant the last one
ended); they are one run. ``Log.clock_runs`` splits a log's runs with it, ``verify`` notes it,
and ``metrics`` starts a fresh continuity window after it, so the three always agree.
"""

from __future__ import annotations

__all__ = ["clock_restarted"]


def clock_restarted(before_ns: int, after_ns: int) -> bool:
    """True when a stretch starting at ``after_ns`` follows one that ended at ``before_ns`` on a
    clock that went back."""
    return after_ns < before_ns
