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
        "(signals: command.*, channel.*, nearest.*, factor.*, check.*, flag.*)"
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
