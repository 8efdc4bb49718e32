"""cycle_fields: a field read from the canonical bytes equals the full parse."""

from __future__ import annotations

from pathlib import Path

from trace_audit.cycle_fields import command_of
from trace_runtime import open_log


def test_command_of_matches_the_full_parse(sample_log: Path) -> None:
    for cycle in open_log(sample_log).iter_cycles():
        action = cycle.action
        assert action is not None and command_of(cycle) == action.command
