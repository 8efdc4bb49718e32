"""Times as the investigator takes them: integer ns in the log's clock, or CLI text.

The library takes integer nanoseconds in the log's own clock (``t_ns``). At the CLI a time
is seconds in that clock (``12.3`` means t_ns = 12_300_000_000); ``+12.3`` means 12.3 s
after the log's first record. ``TimePoint.parse`` reads both and ``resolve_time`` turns any
of them into ``t_ns`` for a given log, so every command reads times the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from decimal import Decimal, InvalidOperation

from trace_runtime.errors import UsageError
from trace_runtime.logset import Log

__all__ = ["TimeArg", "TimePoint", "resolve_time"]


@dataclass(frozen=True, slots=True)
class TimePoint:
    """A time as given at the CLI: seconds in the log's clock, or ``+S`` after its start."""

    ns: int
    relative: bool = False

    @classmethod
    def parse(cls, text: str) -> TimePoint:
        """Read ``12.3``, ``12.3s`` or ``+12.3`` (relative to the log start); UsageError else."""
        raw = text.strip()
        relative = raw.startswith("+")
        number = raw[1:] if relative else raw
        number = number[:-1] if number.endswith("s") else number
        try:
            seconds = Decimal(number)
        except InvalidOperation:
            seconds = Decimal("NaN")
        if not seconds.is_finite() or seconds < 0 or number.strip() != number or not number:
            raise UsageError(
                f"invalid time {text!r}: give seconds in the log's clock (e.g. 12.3) "
                "or +seconds after the log start (e.g. +5)"
            )
        return cls(int(seconds * 1_000_000_000), relative)

    def resolve(self, log: Log) -> int:
        """This time as ``t_ns`` in ``log``'s clock."""
        return log.start_ns + self.ns if self.relative else self.ns


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
