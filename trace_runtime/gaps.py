"""The one gap rule: when the time between two sealed cycles of a robot is a gap.

Every reader that reports gaps (``trace-audit metrics`` for TC, ``timeline``, ``info``,
``verify``) asks here, so they agree on what a gap is, how long it is and how many cycles it
would have held. The rule (docs/metrics.md, "Temporal Continuity"):

- Only sealed cycles of one robot, in chain order, are compared; an unsealed tail closes no
  interval, and two robots' cycles are never compared with each other.
- The interval between two consecutive sealed cycles is a **gap** when it is longer than
  ``(1 + tolerance) x period`` (``period_ns`` of the ``trace.session`` of the segment that
  holds the later cycle). ``DEFAULT_GAP_TOLERANCE`` is 0.5 periods: at 10 Hz, a cycle sealed
  up to 150 ms after the previous one is jitter; one missing cycle (200 ms) is a gap.
- The gap's length (``Gap.gap_ns``) is the time beyond one period, ``interval - period``;
  the cycles it would have held are ``round(gap_ns / period)``.
- A time that is not after the previous sealed cycle's is a clock anomaly: no interval.

``CycleRange`` is the one type for "which cycles and times does this stretch of log cover",
merged with ``merge()`` instead of hand-kept min/max fields.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import NamedTuple

from trace_runtime.errors import UsageError

__all__ = [
    "DEFAULT_GAP_TOLERANCE",
    "JSON_INLINE",
    "NOWHERE",
    "CycleRange",
    "Gap",
    "GapFinder",
    "SealedStamp",
    "check_tolerance",
    "continuity",
    "find_gap",
    "find_gaps",
    "gap_limit_ns",
]

DEFAULT_GAP_TOLERANCE = 0.5
"""Periods of lateness tolerated before an interval between sealed cycles is a gap."""


def check_tolerance(tolerance: float) -> float:
    """``tolerance`` if it is a finite number >= 0; ``UsageError`` otherwise."""
    if not (tolerance >= 0 and tolerance != float("inf")):
        raise UsageError(f"gap tolerance must be a finite number >= 0, got {tolerance}")
    return tolerance


def gap_limit_ns(period_ns: int, tolerance: float = DEFAULT_GAP_TOLERANCE) -> int:
    """The longest interval between sealed cycles that is not a gap: (1 + tolerance) periods."""
    return period_ns + int(period_ns * tolerance)


@dataclass(frozen=True, slots=True)
class Gap:
    """Time between two consecutive sealed cycles of a robot beyond what the period allows.

    ``after_*`` is the last sealed cycle before the gap, ``before_*`` the first after it.
    ``gap_ns`` is the time beyond one period (what TC counts as lost), ``missing_cycles``
    the cycles it would have held at the nominal period, ``declared_dropped`` the count of
    dropped cycles the seal after the gap declares (None when it was not read).
    """

    robot: str
    after_cycle: int
    after_t_ns: int
    before_cycle: int
    before_t_ns: int
    period_ns: int
    gap_ns: int
    missing_cycles: int
    declared_dropped: int | None = None

    @property
    def interval_ns(self) -> int:
        """The whole interval between the two sealed cycles (``gap_ns`` + one period)."""
        return self.before_t_ns - self.after_t_ns


def find_gap(
    after_cycle: int,
    after_t_ns: int,
    before_cycle: int,
    before_t_ns: int,
    period_ns: int,
    *,
    tolerance: float = DEFAULT_GAP_TOLERANCE,
    declared_dropped: int | None = None,
    robot: str = "",
) -> Gap | None:
    """The gap between two consecutive sealed cycles of one robot, or None when there is none.

    No gap without a nominal period (``period_ns <= 0``) or across a clock anomaly.
    """
    interval = before_t_ns - after_t_ns
    if period_ns <= 0 or interval <= gap_limit_ns(period_ns, tolerance):
        return None
    gap = interval - period_ns
    return Gap(
        robot=robot,
        after_cycle=after_cycle,
        after_t_ns=after_t_ns,
        before_cycle=before_cycle,
        before_t_ns=before_t_ns,
        period_ns=period_ns,
        gap_ns=gap,
        missing_cycles=round(gap / period_ns),
        declared_dropped=declared_dropped,
    )


def continuity(interval_ns: int, period_ns: int, tolerance: float = DEFAULT_GAP_TOLERANCE) -> float:
    """A decision's continuity (TCS): 1, or period / interval when the interval since the
    previous sealed cycle is a gap."""
    if period_ns > 0 and interval_ns > gap_limit_ns(period_ns, tolerance):
        return period_ns / interval_ns
    return 1.0


class SealedStamp(NamedTuple):
    """What the gap rule needs of one sealed cycle."""

    cycle: int
    t_ns: int
    period_ns: int
    """The nominal period of the segment that holds the cycle."""
    dropped: int | None = None
    """The ``dropped`` count its seal declares (None: not read)."""


def find_gaps(
    stamps: Iterable[SealedStamp],
    *,
    tolerance: float = DEFAULT_GAP_TOLERANCE,
    robot: str = "",
) -> Iterator[Gap]:
    """The gaps in one robot's sealed cycles, given in chain order."""
    finder = GapFinder(tolerance)
    for stamp in stamps:
        gap = finder.step(robot, stamp)
        if gap is not None:
            yield gap


class GapFinder:
    """Applies the rule to a stream of sealed cycles of one or more robots (each in chain
    order), remembering the last sealed cycle of each robot."""

    __slots__ = ("_last", "tolerance")

    def __init__(self, tolerance: float = DEFAULT_GAP_TOLERANCE) -> None:
        self.tolerance = check_tolerance(tolerance)
        self._last: dict[str, tuple[int, int]] = {}

    def step(self, robot: str, stamp: SealedStamp) -> Gap | None:
        """The gap that ends at this sealed cycle of ``robot``, if any."""
        last = self._last.get(robot)
        self._last[robot] = (stamp.cycle, stamp.t_ns)
        if last is None:
            return None
        return find_gap(
            last[0],
            last[1],
            stamp.cycle,
            stamp.t_ns,
            stamp.period_ns,
            tolerance=self.tolerance,
            declared_dropped=stamp.dropped,
            robot=robot,
        )


# --- cycle ranges ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CycleRange:
    """The cycles and times a stretch of log covers: first..last cycle, start..end time.

    Any end may be unknown (None): a finding located by a cycle but not a time, or a range
    whose end lies beyond what the log holds. ``CycleRange()`` is "nowhere". ``merge`` keeps,
    per end, the outermost value known on either side.
    """

    first_cycle: int | None = None
    last_cycle: int | None = None
    start_ns: int | None = None
    end_ns: int | None = None

    @classmethod
    def of(cls, cycle: int, t_ns: int | None) -> CycleRange:
        """The range of one cycle."""
        return cls(cycle, cycle, t_ns, t_ns)

    def merge(self, other: CycleRange | None) -> CycleRange:
        """The smallest range covering both (``other`` None: this one)."""
        if other is None:
            return self
        return CycleRange(
            _outer(min, self.first_cycle, other.first_cycle),
            _outer(max, self.last_cycle, other.last_cycle),
            _outer(min, self.start_ns, other.start_ns),
            _outer(max, self.end_ns, other.end_ns),
        )

    def extend(self, cycle: int, t_ns: int) -> CycleRange:
        """This range grown to cover one more cycle."""
        return self.merge(CycleRange.of(cycle, t_ns))

    @staticmethod
    def merge_all(ranges: Iterable[CycleRange | None]) -> CycleRange | None:
        """The range covering every given range (None when none is given)."""
        out: CycleRange | None = None
        for item in ranges:
            if item is not None:
                out = item.merge(out)
        return out

    @property
    def duration_ns(self) -> int | None:
        """``end_ns - start_ns``; None when either time is unknown."""
        if self.start_ns is None or self.end_ns is None:
            return None
        return self.end_ns - self.start_ns

    def __contains__(self, cycle: object) -> bool:
        """A cycle from ``first_cycle`` to ``last_cycle`` (only ``first_cycle`` itself when the
        last is unknown; nothing when the first is)."""
        if not isinstance(cycle, int) or self.first_cycle is None:
            return False
        last = self.first_cycle if self.last_cycle is None else self.last_cycle
        return self.first_cycle <= cycle <= last


NOWHERE = CycleRange()
"""The range of something that is not located in cycles or time."""

JSON_INLINE = "json_inline"
"""Dataclass field metadata key: ``trace_audit.jsonout`` writes the field's own fields in its
place, so a ``CycleRange`` field appears in JSON as its four keys beside the others."""


def _outer(pick: Callable[[int, int], int], a: int | None, b: int | None) -> int | None:
    if a is None:
        return b
    if b is None:
        return a
    return pick(a, b)
