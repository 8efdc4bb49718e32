"""Times as the investigator takes and shows them: integer ns in the log's clock, or text.

The library takes integer nanoseconds in the log's own clock (``t_ns``). At the CLI a time
is seconds in that clock (``12.3`` means t_ns = 12_300_000_000); ``+12.3`` means 12.3 s
after the log's first record; on a wall clock (``trace_runtime.clock.is_wall_clock``) an
ISO 8601 time (``2026-05-04T06:04:25.9Z``, or with an offset, ``+02:00``) names the moment.
``TimePoint.parse`` reads all three and ``resolve_time`` turns any of them into ``t_ns`` for
a given log, so every command reads times the same way.

``LogClock`` is the other direction: a time as a person reads it (ISO UTC and seconds since
the log's start on a wall clock, seconds otherwise), and as a command line takes it back
exactly (``LogClock.arg``: every printed command names the same nanosecond).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from decimal import Decimal, InvalidOperation

from trace_runtime.clock import is_wall_clock, iso_utc, show_time
from trace_runtime.errors import UsageError
from trace_runtime.reading.logset import Log

__all__ = [
    "SECONDS_CLOCK",
    "LogClock",
    "NotWallClockError",
    "TimeArg",
    "TimePoint",
    "exact_seconds",
    "hour_of",
    "resolve_time",
]

_ISO = re.compile(
    r"(\d{4}-\d{2}-\d{2})[T ](\d{2}):(\d{2})(?::(\d{2})(?:[.,](\d{1,9}))?)?"
    r"([Zz]|[+-]\d{2}:?\d{2})?"
)
_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


@dataclass(frozen=True, slots=True)
class TimePoint:
    """A time as given at the CLI: seconds in the log's clock, or ``+S`` after its start."""

    ns: int
    relative: bool = False
    wall: bool = False
    """Given as an ISO 8601 time: ``ns`` since the Unix epoch, for a wall-clock log only."""

    @classmethod
    def parse(cls, text: str) -> TimePoint:
        """Read ``12.3``, ``12.3s``, ``+12.3`` (relative to the log start) or an ISO 8601
        time; UsageError else."""
        raw = text.strip()
        if _ISO.fullmatch(raw):
            return cls(_iso_ns(raw), wall=True)
        relative = raw.startswith("+")
        number = raw[1:] if relative else raw
        number = number[:-1] if number.endswith("s") else number
        try:
            seconds = Decimal(number)
        except InvalidOperation:
            seconds = Decimal("NaN")
        if not seconds.is_finite() or seconds < 0 or number.strip() != number or not number:
            raise UsageError(
                f"invalid time {text!r}: give seconds in the log's clock (e.g. 12.3), "
                "+seconds after the log start (e.g. +5) or, on a wall clock, an ISO 8601 "
                "time (e.g. 2026-05-04T06:04:25Z)"
            )
        return cls(int(seconds * 1_000_000_000), relative)

    def resolve(self, log: Log) -> int:
        """This time as ``t_ns`` in ``log``'s clock."""
        if self.wall and not is_wall_clock(log.clock, log.start_ns):
            raise NotWallClockError(
                f"this log's times are seconds on its own clock ({log.clock!r}), not times of "
                "day: give seconds (e.g. 12.3) or +seconds after the log start"
            )
        return log.start_ns + self.ns if self.relative else self.ns


class NotWallClockError(UsageError):
    """An ISO 8601 time was given for a log whose clock tells no time of day."""


def _iso_ns(text: str) -> int:
    """Nanoseconds since the Unix epoch of an ISO 8601 time (UTC when no offset is given)."""
    found = _ISO.fullmatch(text)
    assert found is not None
    day, hour, minute, second, fraction, zone = found.groups()
    try:
        moment = datetime.fromisoformat(f"{day}T{hour}:{minute}:{second or '00'}")
    except ValueError as err:
        raise UsageError(f"invalid time {text!r}: {err}") from None
    offset = timedelta(0)
    if zone and zone not in "Zz":
        digits = zone[1:].replace(":", "")
        offset = timedelta(hours=int(digits[:2]), minutes=int(digits[2:]))
        offset = -offset if zone[0] == "-" else offset
    whole = (moment.replace(tzinfo=UTC) - offset - _EPOCH) // timedelta(seconds=1)
    return whole * 1_000_000_000 + int((fraction or "0").ljust(9, "0"))


def exact_seconds(t_ns: int) -> str:
    """``t_ns`` as seconds with every nanosecond kept (``1777874664.9``): the text
    ``TimePoint.parse`` reads back to the same ``t_ns``, never rounded like ``:.9g``."""
    sign, t_ns = ("-", -t_ns) if t_ns < 0 else ("", t_ns)
    whole, part = divmod(t_ns, 1_000_000_000)
    fraction = f"{part:09d}".rstrip("0")
    return f"{sign}{whole}.{fraction}" if fraction else f"{sign}{whole}"


@dataclass(frozen=True, slots=True)
class LogClock:
    """How a log's times are shown to a person and given back on a command line.

    ``name`` is the segments' ``clock``; ``start_ns`` the log's first time. On a wall clock a
    time reads ``2026-05-04T06:04:25.900Z (+265.000 s)``: the UTC moment and the seconds
    since the log's start; on any other clock, ``265.000 s``."""

    name: str
    start_ns: int

    @classmethod
    def of(cls, log: Log) -> LogClock:
        return cls(log.clock, log.start_ns)

    @property
    def wall(self) -> bool:
        return is_wall_clock(self.name, self.start_ns)

    def show(self, t_ns: int) -> str:
        """A time as people read it, to the millisecond (``clock.show_time``)."""
        return show_time(t_ns, self.name, self.start_ns)

    def iso(self, t_ns: int, *, digits: int = 9) -> str:
        """The UTC moment of a wall-clock time (``clock.iso_utc``)."""
        return iso_utc(t_ns, digits=digits)

    def arg(self, t_ns: int) -> str:
        """The text a command line takes back to exactly ``t_ns``: ISO on a wall clock,
        seconds otherwise."""
        return self.iso(t_ns) if self.wall else exact_seconds(t_ns)


TimeArg = TimePoint | int | str | None


def resolve_time(value: TimeArg, log: Log) -> int | None:
    """``t_ns`` for a time given as TimePoint, int nanoseconds or CLI text (None stays None)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | str | TimePoint):
        raise TypeError(f"a time is int ns, CLI text or a TimePoint, not {type(value).__name__}")
    if isinstance(value, int):
        return value
    if isinstance(value, str):
        value = TimePoint.parse(value)
    return value.resolve(log)


SECONDS_CLOCK = LogClock("system", 0)
"""A clock that tells no time of day: times shown as seconds (a result's default)."""

_HOUR_NS = 3600 * 1_000_000_000


def hour_of(t_ns: int, wall: bool) -> str:
    """The hour a time falls in, as ``metrics --by hour`` and the fleet index name it: the
    UTC hour (``2026-05-04 06:00``) on a wall clock, else the hour of the robot's own clock
    (``+0003h``: 3 to 4 hours after its zero), never an hour of 1970."""
    if not wall:
        return f"+{t_ns // _HOUR_NS:04d}h"
    return (_EPOCH + timedelta(seconds=t_ns // 1_000_000_000)).strftime("%Y-%m-%d %H:00")
