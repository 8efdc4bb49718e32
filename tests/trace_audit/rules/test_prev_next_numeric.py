"""prev and next of a number read the previous and next cycle's value, however rtamt's
grammar would bind them."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.conftest import PERIOD_NS
from tests.trace_audit.rules.check_helpers import rule_text
from trace_audit.rules import Outcome, check_rules, parse_rules
from trace_audit.rules.formula import compile_formula


def test_next_and_prev_of_a_number_read_the_next_and_previous_cycle() -> None:
    speed = [0.0, 1.0, 3.0, 3.0, 7.0]
    nxt = compile_formula(
        "n", "always(abs(next(channel.speed.actual) - channel.speed.actual) <= 0.01)"
    )
    got = nxt.evaluate({"channel.speed.actual": speed}, PERIOD_NS)
    # 0.01 - |s[i+1] - s[i]|, by hand; the last cycle has no next (not decidable anyway)
    assert got[:4] == [pytest.approx(v) for v in (-0.99, -1.99, 0.01, -3.99)]
    prv = compile_formula(
        "p", "always(abs(prev(channel.speed.actual) - channel.speed.actual) <= 0.01)"
    )
    got = prv.evaluate({"channel.speed.actual": speed}, PERIOD_NS)
    assert got[1:] == [pytest.approx(v) for v in (-0.99, -1.99, 0.01, -3.99)]
    stop = compile_formula("s", "always(next(command.STOP) <= command.STOP)")
    got = stop.evaluate({"command.STOP": [0.0, 1.0, 1.0, 0.0, 1.0]}, PERIOD_NS)
    assert got[:4] == [pytest.approx(v) for v in (-1.0, 0.0, 1.0, -1.0)]


def test_next_stop_rule_counts_each_start_of_stop(sample_log: Path) -> None:
    from trace_audit.transitions import why

    rules = parse_rules(rule_text("starts", "always(next(command.STOP) <= command.STOP)"))
    (rule,) = check_rules(sample_log, rules).robots[0].rules
    assert rule.outcome is Outcome.VIOLATED
    assert len(rule.violations) == len(why(sample_log, "STOP").transitions)
