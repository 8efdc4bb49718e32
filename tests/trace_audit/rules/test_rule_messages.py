"""The rules file's error messages: one line that says what to write."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.rules.check_helpers import rule_text
from trace_audit.rules import RulesError, check_rules, parse_rules


def test_a_name_that_is_not_text_says_it_must_be_text() -> None:
    with pytest.raises(RulesError) as err:
        parse_rules('[[rule]]\nname = 5\nstl = "always(command.STOP < 0.5)"\n', "r.toml")
    assert str(err.value) == 'r.toml: rule #1: name must be text (name = "...")'
    with pytest.raises(RulesError, match="rule #1 has no name"):
        parse_rules('[[rule]]\nstl = "always(command.STOP < 0.5)"\n', "r.toml")
    with pytest.raises(RulesError, match="rule 'a': stl must be text"):
        parse_rules('[[rule]]\nname = "a"\nstl = 5\n', "r.toml")


@pytest.mark.parametrize(
    ("stl", "suggested"),
    [
        ("always(once(command.STOP > 0.5))", "once[0:0.5](...)"),
        ("always(historically(command.STOP > 0.5))", "historically[0:0.5](...)"),
        ("always(eventually(command.STOP > 0.5))", "eventually[0:0.5](...)"),
        ("always(command.STOP > 0.5 since command.GO > 0.5)", "a since[0:0.5] b"),
    ],
)
def test_an_unbounded_operator_suggests_a_bound_on_that_operator(stl: str, suggested: str) -> None:
    with pytest.raises(RulesError) as err:
        parse_rules(rule_text("r", stl), "r.toml")
    assert f"e.g. {suggested}" in str(err.value) and "\n" not in str(err.value)


def test_an_unknown_signal_family_is_named_with_the_families() -> None:
    with pytest.raises(RulesError) as err:
        parse_rules(rule_text("r", "always(bogus.x > 1 and command.STOP < 0.5)"), "r.toml")
    assert str(err.value) == (
        "r.toml: rule 'r': unknown signal 'bogus.x' "
        "(signals: command.*, channel.*, nearest.*, factor.*, check.*, flag.*, perception.*, "
        "evidence.*)"
    )


def test_a_bound_not_in_whole_cycles_names_the_file_the_bound_and_the_period(
    sample_log: Path,
) -> None:
    rules = parse_rules(rule_text("r", "always(eventually[0:0.05](command.STOP > 0.5))"), "r.toml")
    with pytest.raises(RulesError) as err:
        check_rules(sample_log, rules, rules_file="r.toml")
    text = str(err.value)
    assert text.startswith("r.toml: rule 'r': ")
    assert "the bound 0.05 s" in text and "0.1 s" in text and "\n" not in text


@pytest.mark.parametrize(
    ("stl", "shown"),
    [
        ("always(eventually[0.5:0.2](command.STOP > 0.5))", "eventually[0.5:0.2]"),
        ("always(eventually[-1:0](command.STOP > 0.5))", "eventually[-1:0]"),
        ("always(once[0.3:0](command.STOP > 0.5))", "once[0.3:0]"),
    ],
)
def test_a_reversed_or_negative_interval_is_refused(stl: str, shown: str) -> None:
    with pytest.raises(RulesError) as err:
        parse_rules(rule_text("r", stl), "r.toml")
    assert f"the interval of {shown} must be [a:b] with 0 <= a <= b" in str(err.value)


def test_an_unclosed_parenthesis_is_said_as_such() -> None:
    with pytest.raises(RulesError, match=r"unbalanced parentheses \(2 opened, 0 closed\)"):
        parse_rules(rule_text("r", "always(nearest.person > (1.0"), "r.toml")


def test_a_signal_the_log_never_shows_is_named_under_its_rule(tmp_path: Path) -> None:
    from sim.faults import FaultRates
    from sim.runner import RunConfig, run

    run(RunConfig(out=tmp_path / "run", total_cycles=300, seed=1, faults=FaultRates.off()))
    text = rule_text("typo", "always(nearest.persn >= 0.5)") + rule_text(
        "fine", "always(nearest.person >= 0.1 or command.STPO > 0.5)"
    )
    typo, fine = check_rules(tmp_path / "run", parse_rules(text)).robots[0].rules
    assert typo.unseen == ("nearest.persn",) and typo.outcome.value == "satisfied"
    assert fine.unseen == ("command.STPO",)


def test_a_robot_the_window_misses_is_named_not_left_out(tmp_path: Path) -> None:
    from sim.faults import FaultRates
    from sim.runner import RunConfig, run

    root = tmp_path / "root"
    for robot, cycles in (("short", 100), ("long", 400)):
        run(RunConfig(out=root, total_cycles=cycles, robot_id=robot, faults=FaultRates.off()))
    rules = parse_rules(rule_text("r", "always(command.STOP < 2)"))
    result = check_rules(root, rules, start="30")
    assert [r.robot for r in result.robots] == ["long"]
    (skipped,) = result.skipped
    assert skipped.robot == "short" and "does not overlap" in skipped.reason
