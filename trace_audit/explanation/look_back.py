"""Looking back from a decision, bounded: one reverse walk finds the previous seal (for the
hash chain), the sensor readings of the cycles before (evidence refs may point at them), and
the cycle where the current command began. When the walk reaches its bound first, the
command has held "at least since" the oldest cycle seen."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Literal

from trace_audit.cycle_fields import command_of
from trace_audit.explanation.result import HeldSince
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.logset import Log
from trace_runtime.records import TOPIC_SEAL

__all__ = ["LookBack", "look_back"]


@dataclass(slots=True)
class LookBack:
    """What one walk back from a decision found: the sensor window (newest first), the
    previous sealed cycle, and since when the command has held."""

    window: list[Cycle]
    prev_sealed: Cycle | None
    held: HeldSince


def look_back(
    log: Log,
    target: Cycle,
    command: str | None,
    lookback_ns: int,
    window_cycles: int,
    *,
    period_ns: int,
) -> LookBack:
    """One reverse walk: previous seal, where the current command began, sensor window.

    The walk reads at most ``lookback_ns`` of log (or the sensor window, if longer) and
    stops as soon as it has what it needs; ``window_cycles=0`` skips the window. Only a gap
    longer than that before the decision sends it further back, for the previous seal.
    """
    window: list[Cycle] = []
    prev_sealed: Cycle | None = None
    since, count = target, 1
    bound: Literal["change", "lookback", "log_start"] = "log_start"
    previous: Cycle | None = None
    holding = True
    floor = target.t_ns - lookback_ns
    start = max(0, min(floor, target.t_ns - 2 * (window_cycles + 1) * period_ns))
    for earlier in _reverse_from(log, target.t_ns, start):
        if earlier.cycle >= target.cycle:
            continue
        if len(window) < window_cycles:
            window.append(earlier)
        if prev_sealed is None and TOPIC_SEAL in earlier.payloads:
            prev_sealed = earlier
        if holding:
            if earlier.t_ns < floor:
                holding, bound = False, "lookback"
            elif command_of(earlier) == command:
                since, count = earlier, count + 1
            else:
                holding, bound, previous = False, "change", earlier
        if not holding and prev_sealed is not None and len(window) >= window_cycles:
            break
    else:
        if holding and start > log.start_ns:
            bound = "lookback"  # the walk's bound, not the log's start, stopped it
        if prev_sealed is None and start > log.start_ns:
            prev_sealed = next(
                (c for c in log.iter_cycles(end_ns=start - 1, reverse=True) if c.sealed),
                None,
            )
    held = HeldSince(
        command=command,
        since_cycle=since.cycle,
        since_t_ns=since.t_ns,
        cycles=count,
        bound=bound,
        previous=command_of(previous) if previous is not None else None,
        previous_cycle=previous.cycle if previous is not None else None,
        at_least=bound != "change",
    )
    return LookBack(window, prev_sealed, held)


def _reverse_from(log: Log, t_ns: int, start_ns: int) -> Iterator[Cycle]:
    """Cycles from ``t_ns`` back to ``start_ns``, newest first, in widening windows.

    The reader lists the chunks of a window before decoding any, so a walk that usually
    stops within a second should not ask for ten minutes at once: windows of 1 s, 10 s,
    100 s, ... up to ``start_ns``.
    """
    hi, span = t_ns, 1_000_000_000
    while hi >= start_ns:
        lo = max(start_ns, t_ns - span)
        yield from log.iter_cycles(start_ns=lo, end_ns=hi, reverse=True)
        hi, span = lo - 1, span * 10
