"""why: the transitions into an action, with the reason logged for each."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.conftest import PERIOD_NS, stretch, t_ns, write_log
from trace_audit.transitions import why
from trace_runtime.errors import TimeOutOfRangeError, UsageError


def test_every_transition_into_stop_with_its_reason(sample_log: Path) -> None:
    r = why(sample_log, "STOP")
    assert r.action == "STOP" and r.t_ns is None
    assert [(x.cycle, x.previous, x.held_cycles, x.next_command) for x in r.transitions] == [
        (40, "SLOW", 20, "CONTINUE"),
        (80, "REROUTE", 5, "CONTINUE"),
    ]
    first = r.transitions[0]
    assert first.rationale == "Pedestrian detected at 1.5m with collision risk 0.70."
    assert first.leading is not None and (first.leading.name, first.leading.value) == (
        "distance",
        1.5,
    )
    assert [c.would_select for c in first.counterfactuals] == ["SLOW", "CONTINUE"]
    assert first.held_ns == 20 * PERIOD_NS and first.ended_t_ns == t_ns(60)
    assert not first.ongoing and first.flags == ()  # the scenario label is not a flag
    assert r.actions_present == {"CONTINUE": 55, "STOP": 25, "SLOW": 10, "REROUTE": 10}


def test_action_is_matched_without_regard_to_case(sample_log: Path) -> None:
    assert why(sample_log, "reroute").action == "REROUTE"


def test_at_t_gives_the_transition_in_force(sample_log: Path) -> None:
    during = why(sample_log, "STOP", t=t_ns(45))
    assert [x.cycle for x in during.transitions] == [40]
    assert during.transitions[0].held_cycles == 20  # followed past t to where it ended
    after = why(sample_log, "stop", t="+6.5")  # STOP had ended by then: the latest one
    assert [x.cycle for x in after.transitions] == [40]
    second = why(sample_log, "STOP", t=t_ns(99))
    assert [x.cycle for x in second.transitions] == [80]


def test_before_the_first_transition_is_a_usage_error_that_says_when(sample_log: Path) -> None:
    with pytest.raises(UsageError, match=r"first taken at t=104.000 s \(cycle 40\)"):
        why(sample_log, "STOP", t=t_ns(10))


def test_unknown_action_lists_the_actions_present(sample_log: Path) -> None:
    with pytest.raises(UsageError, match=r"'DANCE' is never taken.*CONTINUE \(55\), STOP \(25\)"):
        why(sample_log, "DANCE")
    with pytest.raises(UsageError, match="never taken"):
        why(sample_log, "DANCE", t=t_ns(50))


def test_time_outside_the_log(sample_log: Path) -> None:
    with pytest.raises(TimeOutOfRangeError):
        why(sample_log, "STOP", t="+100")


def test_an_action_held_to_the_end_is_ongoing(tmp_path: Path) -> None:
    log = write_log(tmp_path / "r.mcap", [stretch("clear", 5), stretch("ped_close", 5)])
    (x,) = why(log, "STOP").transitions
    assert x.ongoing and x.ended_t_ns is None and x.next_command is None
    assert x.held_ns == 5 * PERIOD_NS
    (first,) = why(log, "CONTINUE").transitions
    assert first.previous is None and first.previous_cycle is None  # the log starts with it


def test_flags_of_the_transition_cycle_are_reported(tmp_path: Path) -> None:
    log = write_log(tmp_path / "r.mcap", [stretch("clear", 3), stretch("ped_close", 2, "flag")])
    (x,) = why(log, "STOP").transitions
    assert x.flags == ("deviation_high",)


def test_a_truncated_rationale_is_marked(tmp_path: Path) -> None:
    log = write_log(
        tmp_path / "r.mcap", [stretch("clear", 3), stretch("ped_close", 2, "truncated")]
    )
    (x,) = why(log, "STOP").transitions
    assert x.truncated and x.rationale == "Pedestrian d"


def test_dropped_cycles_before_a_transition_are_said(tmp_path: Path) -> None:
    log = write_log(
        tmp_path / "r.mcap",
        [stretch("clear", 5), stretch("ped_close", 5)],
        skip=lambda i: i in (4, 5),
    )
    (x,) = why(log, "STOP").transitions
    assert (x.cycle, x.previous_cycle, x.unlogged_before) == (6, 3, 2)
