"""The execution record's flag vocabulary that readers interpret rather than only show.

A ``scenario:NAME`` flag labels the situation a cycle ran in (a test scenario, a field trial);
it reports no problem, so warm retention does not keep a cycle for it, ``metrics`` groups by
it, and the causal view shows it as a label rather than a finding.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["SCENARIO_FLAG", "split_flags"]

SCENARIO_FLAG = "scenario:"
"""A flag of this form labels the situation (e.g. a test scenario); it reports no problem."""


def split_flags(flags: Iterable[object]) -> tuple[tuple[str, ...], str | None]:
    """(the flags that report something, the first non-empty ``scenario:`` label or None).

    Only strings are flags; anything else in the list is passed over.
    """
    real: list[str] = []
    scenario: str | None = None
    for flag in flags:
        if not isinstance(flag, str):
            continue
        if flag.startswith(SCENARIO_FLAG):
            scenario = scenario or flag[len(SCENARIO_FLAG) :] or None
        else:
            real.append(flag)
    return tuple(real), scenario
