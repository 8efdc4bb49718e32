"""check_rules: STL rules judged by rtamt on each robot's gap-free stretches."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests.trace_audit.conftest import stretch, t_ns, write_log
from tests.trace_audit.rules.check_helpers import rule_text
from trace_audit.rules import Outcome, RulesError, UndecidedReason, check_rules, parse_rules
from trace_audit.rules.formula import rtamt_module
from trace_audit.transitions import why

NEVER_STOP = '[[rule]]\nname = "never_stop"\nstl = "always(command.STOP < 0.5)"\n'


def test_never_stop_fails_exactly_where_why_says_stop_was_in_force(sample_log: Path) -> None:
    result = check_rules(sample_log, parse_rules(NEVER_STOP))
    (rule,) = result.robots[0].rules
    assert rule.outcome is Outcome.VIOLATED and result.violated
    assert rule.robustness == pytest.approx(-0.5)
    expected = [
        (tr.cycle, tr.cycle + tr.held_cycles - 1, tr.t_ns, tr.last_t_ns)
        for tr in why(sample_log, "STOP").transitions
    ]
    got = [(v.first_cycle, v.last_cycle, v.start_ns, v.end_ns) for v in rule.violations]
    assert got == expected
    first = rule.violations[0]
    assert first.command == "STOP" and first.cycles == 20
    assert first.explain == f"trace-audit explain {sample_log} --cycle 40 --robot amr-7"


def test_a_rule_that_holds_is_satisfied(sample_log: Path) -> None:
    rules = parse_rules(
        rule_text(
            "no_continue_close", "always((nearest.person < 2.0) implies (command.CONTINUE < 0.5))"
        )
    )
    (rule,) = check_rules(sample_log, rules).robots[0].rules
    assert rule.outcome is Outcome.SATISFIED and rule.violations == () and rule.undecided == ()
    assert rule.decidable_cycles == 100


def test_a_window_across_a_gap_is_not_decidable_and_names_the_gap(tmp_path: Path) -> None:
    log = write_log(tmp_path / "gap.mcap", [stretch("clear", 40)], skip=lambda i: 20 <= i < 25)
    rules = parse_rules(rule_text("soon_stop", "always(eventually[0:0.3](command.CONTINUE > 0.5))"))
    (rule,) = check_rules(log, rules).robots[0].rules
    assert rule.outcome is Outcome.NOT_DECIDABLE and rule.violations == ()
    gap = next(u for u in rule.undecided if u.reason is UndecidedReason.GAP)
    # cycles 17..19 look 3 cycles ahead, into the gap; 20..24 were never logged
    assert (gap.first_cycle, gap.last_cycle, gap.logged_cycles) == (17, 24, 3)
    assert gap.gap is not None and gap.gap.after_cycle == 19 and gap.gap.missing_cycles == 5
    end = rule.undecided[-1]
    assert end.reason is UndecidedReason.LOG_END and (end.first_cycle, end.last_cycle) == (37, 39)
    assert rule.decidable_cycles == 40 - 5 - 3 - 3


def test_a_gap_alone_makes_even_a_pointwise_rule_not_decidable(tmp_path: Path) -> None:
    log = write_log(tmp_path / "gap.mcap", [stretch("clear", 30)], skip=lambda i: i == 10)
    (rule,) = check_rules(log, parse_rules(NEVER_STOP)).robots[0].rules
    assert rule.outcome is Outcome.NOT_DECIDABLE
    assert [(u.reason, u.first_cycle, u.last_cycle, u.logged_cycles) for u in rule.undecided] == [
        (UndecidedReason.GAP, 10, 10, 0)
    ]


def test_the_window_is_judged_on_real_cycles_around_it(sample_log: Path) -> None:
    rules = parse_rules(rule_text("r", "always(eventually[0:0.5](command.CONTINUE > -1))"))
    (rule,) = check_rules(sample_log, rules, start=t_ns(10), end=t_ns(19)).robots[0].rules
    assert rule.outcome is Outcome.SATISFIED and rule.decidable_cycles == 10
    assert rule.undecided == ()


def test_robustness_is_rtamts_on_a_hand_made_signal(tmp_path: Path) -> None:
    script = [
        stretch("clear", 5),
        stretch("ped_far", 4),
        stretch("ped_close", 6),
        stretch("clear", 5),
    ]
    log = write_log(tmp_path / "tiny.mcap", script)
    body = "(nearest.person < 3.0) implies eventually[0:0.2](command.STOP > 0.5)"
    (rule,) = check_rules(log, parse_rules(rule_text("r", f"always({body})"))).robots[0].rules
    nearest = [math.inf] * 5 + [3.2] * 4 + [1.5] * 6 + [math.inf] * 5
    stop = [0.0] * 9 + [1.0] * 6 + [0.0] * 5
    spec = rtamt_module().StlDiscreteTimeSpecification()
    spec.declare_var("dist", "float")
    spec.declare_var("stopped", "float")
    spec.set_sampling_period(100, "ms", 0.1)
    spec.spec = "(dist < 3.0) implies eventually[0:0.2](stopped > 0.5)"
    spec.parse()
    out = spec.evaluate({"time": [i / 10 for i in range(20)], "dist": nearest, "stopped": stop})
    decidable = [value for _, value in out][:-2]  # the last two look past the log's end
    assert rule.robustness == pytest.approx(min(decidable))
    assert rule.decidable_cycles == 18
    assert rule.outcome is Outcome.SATISFIED and math.isfinite(min(decidable))


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[[rule]\nname = 'x'", "not valid TOML"),
        ('[[rule]]\nname = "bad"\nstl = "always(command.STOP < "\n', "rule 'bad'"),
        (
            '[[rule]]\nname = "open"\nstl = "always(eventually(command.STOP > 0.5))"\n',
            "rule 'open'",
        ),
        ('[[rule]]\nname = "top"\nstl = "command.STOP > 0.5"\n', "rule 'top': a rule is always"),
        ('[[rule]]\nname = "who"\nstl = "always(speed < 1)"\n', "rule 'who': unknown signal"),
        ('[[rule]]\nname = "ch"\nstl = "always(channel.speed < 1)"\n', "rule 'ch': channel.speed"),
        ("title = 'no rules'\n", "no rules"),
    ],
)
def test_a_bad_rules_file_is_one_usage_error_naming_the_rule(text: str, words: str) -> None:
    with pytest.raises(RulesError, match=None) as err:
        parse_rules(text, "rules.toml")
    assert words in str(err.value) and "\n" not in str(err.value)


def test_a_bound_off_the_log_period_names_the_rule(sample_log: Path) -> None:
    rules = parse_rules(rule_text("odd", "always(eventually[0:0.25](command.STOP > 0.5))"))
    with pytest.raises(RulesError, match=r"rule 'odd'.*multiple of the sampling period"):
        check_rules(sample_log, rules)
