"""check on a stretch of one cycle (a window of one cycle, a cycle between two gaps):
judged where the rule's horizon allows, never an rtamt traceback."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.conftest import PERIOD_NS, stretch, write_log
from tests.trace_audit.rules.check_helpers import rule_text, rules_file, run_check
from trace_audit.rules import Outcome, RulesError, check_rules, parse_rules
from trace_audit.rules.formula import compile_formula


def test_a_one_cycle_stretch_is_judged_without_rtamt_failing() -> None:
    formula = compile_formula("r", "always(channel.speed.actual <= 1.5)")
    assert formula.evaluate({"channel.speed.actual": [1.0]}, PERIOD_NS) == [pytest.approx(0.5)]
    assert formula.evaluate({"channel.speed.actual": [2.0]}, PERIOD_NS) == [pytest.approx(-0.5)]


def test_a_one_cycle_window_is_judged(sample_log: Path) -> None:
    rules = parse_rules(rule_text("stop", "always(command.STOP < 0.5)"))
    (rule,) = check_rules(sample_log, rules, start="104", end="104").robots[0].rules
    assert rule.outcome is Outcome.VIOLATED and rule.decidable_cycles == 1


def test_a_single_cycle_between_two_gaps_is_judged_or_not_decidable(tmp_path: Path) -> None:
    log = write_log(tmp_path / "one.mcap", [stretch("clear", 30)], skip=lambda i: i in (10, 12))
    text = rule_text("plain", "always(command.STOP < 0.5)") + rule_text(
        "ahead", "always(eventually[0:0.2](command.STOP < 0.5))"
    )
    plain, ahead = check_rules(log, parse_rules(text)).robots[0].rules
    assert plain.outcome is Outcome.NOT_DECIDABLE and plain.violations == ()
    assert plain.decidable_cycles == 28  # cycle 11 alone is judged too
    assert ahead.outcome is Outcome.NOT_DECIDABLE
    code, _, err = run_check(str(log), "--rules", rules_file(tmp_path, text), "--plain")
    assert code == 0 and "Traceback" not in err


def test_an_rtamt_failure_is_one_line_not_a_traceback(monkeypatch: pytest.MonkeyPatch) -> None:
    formula = compile_formula("r", "always(channel.speed.actual <= 1.5)")
    import trace_audit.rules.formula as module

    class Boom:
        def evaluate(self, data: object) -> object:
            raise IndexError("list index out of range")

    monkeypatch.setattr(module.Formula, "_spec", lambda self, period_ns: Boom())
    with pytest.raises(RulesError, match=r"rule 'r'.*rtamt"):
        formula.evaluate({"channel.speed.actual": [1.0, 2.0]}, PERIOD_NS, engine="rtamt")
