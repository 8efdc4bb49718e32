"""``trace-audit check``: safety requirements (STL rules) checked over a log.

Parses its arguments, reads the rules file (``trace_audit.rules.read_rules``), calls
``trace_audit.rules.check_rules`` and renders the typed result: rich on a terminal, plain
text with ``--plain`` or in a pipe, JSON with ``--json``. Exit 1 when a rule is violated.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Doc, Seg
from trace_audit.cli.options import JsonOption, LogArgument, PlainOption, RobotsOption
from trace_audit.cli.output import emit

if TYPE_CHECKING:  # the library (and rtamt) is imported inside the command
    from trace_audit.rules import CheckResult, RobotRules, RuleResult

__all__ = ["check_command", "check_doc"]

_CHECK_HELP = """Check safety requirements over a log: named Signal Temporal Logic rules.

RULES.toml holds [[rule]] tables, each a name and an stl formula always(...) over the
signals the log defines: command.<ACTION> (1 while in force), channel.<name>.intended,
.actual or .deviation (planar robots: channel.speed.*), nearest.<class> (metres), factor.<name>,
check.<rule> (1 passed, 0 failed) and flag.<name>. Times in formulas are seconds of log time;
the rules are evaluated by rtamt in discrete time at the log's cycle period (docs/rules.md).

Each rule is judged per robot: satisfied, violated (with every violation interval, the
decision in force and the command that explains it) or not decidable (a gap or a missing
signal hides part of the window: never interpolated). Robustness is rtamt's: how far the
worst cycle is from the rule's boundary, in the signals' units.

Exit codes: 0 every rule satisfied or not decidable, 1 a rule violated, 2 a bad rules file
or usage (one line naming the rule), 3 an unreadable log.

[bold]Examples[/bold]:

  trace-audit check run.mcap --rules docs/rules/warehouse.toml

  trace-audit check logs/ --rules rules.toml --robot amr-7 --from +60

  trace-audit check run.mcap --rules docs/rules/warehouse.toml --json
"""


@app.command("check", help=help_text(_CHECK_HELP))
def check_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    rules: Annotated[
        Path,
        typer.Option(
            "--rules", help="The rules file (TOML: [[rule]] name, stl).", show_default=False
        ),
    ],
    robot: RobotsOption = None,
    start: Annotated[
        str | None,
        typer.Option(
            "--from",
            help="Start of the window (seconds, +seconds after the log start, or on a wall "
            "clock an ISO 8601 time). Default: the log start.",
            show_default=False,
        ),
    ] = None,
    end: Annotated[
        str | None,
        typer.Option(
            "--to", help="End of the window (same forms). Default: the log end.", show_default=False
        ),
    ] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    result = guarded(lambda: _check(log, rules, robot or (), start, end))
    emit(result, check_doc, json_out=json_out, plain=plain)
    if result.violated:
        raise typer.Exit(EXIT_FINDINGS)


def _check(
    source: Path,
    rules_path: Path,
    robots: list[str] | tuple[str, ...],
    start: str | None,
    end: str | None,
) -> CheckResult:
    from trace_audit.rules import check_rules, read_rules

    rules = read_rules(rules_path)  # before the log: a bad rule is exit 2 without a read
    return check_rules(
        source, rules, robots=tuple(robots), start=start, end=end, rules_file=str(rules_path)
    )


_STYLE = {"satisfied": "green", "violated": "bold red", "not_decidable": "yellow"}
_WORDS = {"satisfied": "satisfied", "violated": "VIOLATED", "not_decidable": "not decidable"}


def check_doc(r: CheckResult) -> Doc:
    """The rules' outcomes, robot by robot, as a document."""
    doc = Doc()
    doc.title(["Rules ", f"{r.rules_file} over {r.path}"])
    for robot in r.robots:
        period = robot.period_ns / 1e9
        doc.heading(f"{robot.robot}: {robot.cycles} cycles at {period:g} s")
        for rule in robot.rules:
            _rule_block(doc, robot, rule)
    return doc


def _rule_block(doc: Doc, robot: RobotRules, rule: RuleResult) -> None:
    outcome = rule.outcome.value
    robustness = "n/a" if rule.robustness is None else f"{rule.robustness:.4g}"
    doc.line(
        [
            Seg(f"[{_WORDS[outcome]}]", _STYLE[outcome]),
            f" {rule.rule}  robustness {robustness}, {rule.decidable_cycles} cycles judged",
        ],
        2,
    )
    doc.line(rule.stl, 4)
    clock = robot.clock
    for v in rule.violations:
        doc.line(
            f"violated {clock.show(v.start_ns)} .. {clock.show(v.end_ns)}  cycles "
            f"{v.first_cycle}-{v.last_cycle} ({v.cycles}), robustness {v.robustness:.4g}, "
            f"command {v.command or '?'}",
            4,
        )
        doc.line(v.explain, 6)
    for u in rule.undecided:
        doc.line(
            f"not decidable {clock.show(u.start_ns)} .. {clock.show(u.end_ns)}  cycles "
            f"{u.first_cycle}-{u.last_cycle}: {u.detail}",
            4,
        )
