"""The gaps of a log read in order: the one gap rule stepped cycle by cycle.

``timeline`` and ``info`` find gaps as they read a log's cycles; the rule is
``trace_runtime.gaps``, applied per robot with the period of each cycle's own segment.
"""

from __future__ import annotations

from collections.abc import Callable

from trace_audit.cycle_fields import seal_dropped
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE, Gap, GapFinder, SealedStamp
from trace_runtime.reading.logset import Log

__all__ = ["gap_stepper"]


def gap_stepper(
    log: Log, tolerance: float = DEFAULT_GAP_TOLERANCE
) -> Callable[[Cycle], Gap | None]:
    """Feed a log's cycles in reading order; get the gap each sealed one ends, by the one
    rule (``trace_runtime.gaps``): per robot, with the period of the cycle's own segment."""
    sessions = {s.path.name: s.session for s in log.segments}
    finder = GapFinder(tolerance)

    def step(cycle: Cycle) -> Gap | None:
        session = sessions.get(cycle.segment)
        if session is None or not cycle.sealed:
            return None
        stamp = SealedStamp(cycle.cycle, cycle.t_ns, session.period_ns, seal_dropped(cycle))
        return finder.step(session.robot_id, stamp)

    return step
