"""Safety requirements checked over the logs: Signal Temporal Logic rules, evaluated by rtamt.

``read_rules`` reads a TOML rules file (each ``[[rule]]`` a name and an ``stl`` formula over
signals the log defines, ``trace_audit.rules.signals``); ``check_rules`` judges each rule on
each selected robot, gap-free stretch by stretch (``trace_audit.rules.check``), and returns a
``CheckResult``: per rule and robot satisfied, violated or not decidable, rtamt's robustness,
every violation with the decision in force and the command that explains it.
``check_index`` judges the same rules, by the same evaluator (``trace_audit.rules.judge``),
over a fleet index's rows. docs/rules.md.
"""

from __future__ import annotations

from trace_audit.rules.check import check_rules
from trace_audit.rules.formula import ENGINES, Formula, Horizon, RulesError, compile_formula
from trace_audit.rules.index_check import IndexQuery, check_index
from trace_audit.rules.results import (
    CheckResult,
    GroupRule,
    GroupRules,
    Outcome,
    RobotRules,
    RuleResult,
    Skipped,
    Undecided,
    UndecidedReason,
    Violation,
)
from trace_audit.rules.rulebook import Rule, parse_rules, read_rules
from trace_audit.rules.signals import FAMILIES, read_signals, signal_names

__all__ = [
    "ENGINES",
    "FAMILIES",
    "CheckResult",
    "Formula",
    "GroupRule",
    "GroupRules",
    "Horizon",
    "IndexQuery",
    "Outcome",
    "RobotRules",
    "Rule",
    "RuleResult",
    "RulesError",
    "Skipped",
    "Undecided",
    "UndecidedReason",
    "Violation",
    "check_index",
    "check_rules",
    "compile_formula",
    "parse_rules",
    "read_rules",
    "read_signals",
    "signal_names",
]
