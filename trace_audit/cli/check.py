"""``trace-audit check``: safety requirements (STL rules) checked over a log.

Parses its arguments, reads the rules file (``trace_audit.rules.read_rules``), calls
``trace_audit.rules.check_rules`` on a log (or, with ``--index``,
``trace_audit.rules.check_index`` over the fleet index's rows, its SQL run by the fleet's
bounded ``run_query``) and renders the typed result: rich on a terminal, plain text with
``--plain`` or in a pipe, JSON with ``--json``. Exit 1 when a rule is violated.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Line, Seg
from trace_audit.cli.options import (
    FromOption,
    JsonOption,
    MemoryLimitOption,
    PlainOption,
    RobotsOption,
    SchedulerOption,
    SqlTimeoutOption,
    ToOption,
    cluster,
    sql_limits,
)
from trace_audit.cli.output import JsonValue, emit
from trace_runtime.errors import UsageError

if TYPE_CHECKING:  # the library (and rtamt) is imported inside the command
    from concurrent.futures import Executor  # ~7 ms every command would pay at start

    from trace_audit.fleet.limits import QueryLimits
    from trace_audit.rules import CheckResult, GroupRules, RobotRules, RuleResult

__all__ = ["check_command", "check_doc", "check_json"]

_CHECK_HELP = """Check safety requirements over a log: named Signal Temporal Logic rules.

RULES.toml holds [[rule]] tables, each a name and an stl formula always(...) over the
signals the log defines: command.<ACTION> (1 while in force), channel.<name>.intended,
.actual or .deviation (planar robots: channel.speed.*), nearest.<class> (metres), factor.<name>,
check.<rule> (1 passed, 0 failed) and flag.<name>. Times in formulas are seconds of log time;
the rules are evaluated with rtamt's semantics in discrete time at the log's cycle period
(docs/rules.md).

Each rule is judged per robot: satisfied, violated (with every violation interval, the
decision in force and the command that explains it) or not decidable (a gap or a missing
signal hides part of the window: never interpolated). Robustness is rtamt's: how far the
worst cycle is from the rule's boundary, in the signals' units. A signal the robot's log
never shows (a class never perceived, a command never in force, a flag never raised) is
named under its rule, as a possible typo; a robot whose log the --from/--to window misses
is named, not left out silently.

With --index IDX instead of a log, the rules are judged over a fleet index (trace-audit
index): the same evaluation and JSON, the signals read with DuckDB per robot in time order,
the gaps from the index's gaps table (a planar robot's channel.speed.* from the decisions'
linear motion). --by robot,day adds the table of
outcomes and robustness minima per robot and day (on a sim clock, per run); --scheduler
judges each robot as one task on a Dask cluster (the same JSON).

Exit codes: 0 every rule satisfied or not decidable, 1 a rule violated, 2 a bad rules file
or usage (one line naming the rule), 3 an unreadable log or index.

[bold]Examples[/bold]:

  trace-audit check run.mcap --rules docs/rules/warehouse.toml

  trace-audit check logs/ --rules rules.toml --robot amr-7 --from +60

  trace-audit check run.mcap --rules docs/rules/warehouse.toml --json

  trace-audit check --index fleet-index/ --rules rules.toml --by robot,day
"""

_LogArgument = Annotated[
    Path | None,
    typer.Argument(
        help="A TRACE segment (.mcap), a directory of segments, or a log root (hot/ warm/ "
        "cold/); or none, with --index.",
        show_default=False,
    ),
]
_Index = Annotated[
    Path | None,
    typer.Option(
        "--index",
        help="Judge the rules over a fleet index (trace-audit index) instead of a log.",
        show_default=False,
    ),
]
_By = Annotated[
    str | None,
    typer.Option(
        "--by",
        help="With --index: robot,day adds the outcomes and robustness minima per robot and "
        "day (per run on a sim or monotonic clock).",
        show_default=False,
    ),
]


@app.command("check", help=help_text(_CHECK_HELP))
def check_command(  # noqa: PLR0917 - typer maps each parameter to an option
    rules: Annotated[
        Path,
        typer.Option(
            "--rules", help="The rules file (TOML: [[rule]] name, stl).", show_default=False
        ),
    ],
    log: _LogArgument = None,
    robot: RobotsOption = None,
    start: FromOption = None,
    end: ToOption = None,
    index: _Index = None,
    by: _By = None,
    memory_limit: MemoryLimitOption = None,
    timeout: SqlTimeoutOption = None,
    scheduler: SchedulerOption = None,
    engine: Annotated[
        str,
        typer.Option(
            "--engine",
            help="auto: rtamt's semantics over whole columns where TRACE covers the "
            "formula's operators (rtamt's interpreter for the rest); rtamt: rtamt's "
            "interpreter alone, sample by sample (the reference; slower).",
        ),
    ] = "auto",
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    def run() -> CheckResult:
        from trace_audit.rules import ENGINES

        if engine not in ENGINES:  # before any read, for a log and an index alike
            raise UsageError(f"--engine is one of {', '.join(ENGINES)}, got {engine!r}")
        if (index is None) == (log is None):
            raise UsageError("give either a log or --index INDEX")
        if index is None:
            assert log is not None
            if any(o is not None for o in (by, memory_limit, timeout, scheduler)):
                raise UsageError("--by, --memory-limit, --timeout and --scheduler need --index")
            return _check(log, rules, robot or (), start, end, engine=engine)
        if start is not None or end is not None:
            raise UsageError("--from/--to are not supported with --index (check the logs)")
        keys = [k.strip() for k in (by or "").split(",") if k.strip()]
        limits = sql_limits(memory_limit, timeout)
        with cluster(scheduler) as executor:
            return _check_index(
                index, rules, robot or (), keys, limits, executor=executor, engine=engine
            )

    result = guarded(run)
    emit(result, check_doc, json_out=json_out, plain=plain, to_json=check_json)
    if result.violated:
        raise typer.Exit(EXIT_FINDINGS)


def _check(
    source: Path,
    rules_path: Path,
    robots: list[str] | tuple[str, ...],
    start: str | None,
    end: str | None,
    *,
    engine: str,
) -> CheckResult:
    from trace_audit.rules import check_rules, read_rules

    rules = read_rules(rules_path)  # before the log: a bad rule is exit 2 without a read
    return check_rules(
        source,
        rules,
        robots=tuple(robots),
        start=start,
        end=end,
        rules_file=str(rules_path),
        engine=engine,
    )


def _check_index(
    index: Path,
    rules_path: Path,
    robots: list[str] | tuple[str, ...],
    by: list[str],
    limits: QueryLimits,
    *,
    executor: Executor | None = None,
    engine: str = "auto",
) -> CheckResult:
    from trace_audit.fleet.folder import load_manifest
    from trace_audit.rules import check_index, read_rules
    from trace_runtime.errors import LogReadError
    from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE

    rules = read_rules(rules_path)  # before the index: a bad rule is exit 2 without a read
    manifest = load_manifest(index)
    if manifest is None:
        raise LogReadError(str(index), "not a fleet index (run trace-audit index first)")
    built = manifest.get("config", {}).get("gap_tolerance")
    if built != DEFAULT_GAP_TOLERANCE:  # the gaps table is the gap rule at that tolerance
        raise UsageError(
            f"the index was built with gap_tolerance {built}, not the rules' "
            f"{DEFAULT_GAP_TOLERANCE}: its gaps are not the rules' (rebuild it)"
        )
    rows = IndexRows(str(index.absolute()), limits)  # absolute: workers' directory may differ
    try:
        return check_index(
            rows,
            rules,
            robots=tuple(robots),
            by=by,
            index=str(index),
            rules_file=str(rules_path),
            executor=executor,
            engine=engine,
        )
    finally:
        rows.close()


def check_json(result: CheckResult) -> JsonValue:
    """The result as JSON data, every non-finite float (an infinite robustness: no person
    ever perceived) ``null``: JSON has no Infinity (docs/rules.md, "Reading robustness")."""
    from trace_audit.jsonout import to_jsonable

    return _finite(to_jsonable(result))


def _finite(value: JsonValue) -> JsonValue:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


class IndexRows:
    """The rules' query function over one index: the fleet's bounded, confined
    ``ColumnSession``, one a thread, opened on first use. It pickles as the index's path
    and bounds alone, so that it travels to a Dask worker (``--scheduler``), which opens
    its own."""

    def __init__(self, index: str, limits: QueryLimits) -> None:
        self.index = index
        self.limits = limits
        self._local = threading.local()

    def __call__(self, sql: str, params: Sequence[Any]) -> dict[str, Any]:
        session = getattr(self._local, "session", None)
        if session is None:
            from trace_audit.fleet import ColumnSession

            session = self._local.session = ColumnSession(self.index, self.limits)
        columns: dict[str, Any] = session(sql, params)
        return columns

    def close(self) -> None:
        """Close this thread's session (the others close with their threads' process)."""
        session = getattr(self._local, "session", None)
        if session is not None:
            session.close()
            self._local.session = None

    def __getstate__(self) -> tuple[str, QueryLimits]:
        return self.index, self.limits

    def __setstate__(self, state: tuple[str, QueryLimits]) -> None:
        self.index, self.limits = state
        self._local = threading.local()


_STYLE = {"satisfied": "green", "violated": "bold red", "not_decidable": "yellow"}
_WORDS = {"satisfied": "satisfied", "violated": "VIOLATED", "not_decidable": "not decidable"}


def check_doc(r: CheckResult) -> Doc:
    """The rules' outcomes, robot by robot, as a document."""
    doc = Doc()
    doc.title(["Rules ", f"{r.rules_file} over {r.path}"])
    for robot in r.robots:
        period = robot.period_ns / 1e9
        cycles = f"{robot.cycles} cycle{'s' if robot.cycles != 1 else ''}"
        doc.heading(f"{robot.robot}: {cycles} at {period:g} s")
        for rule in robot.rules:
            _rule_block(doc, robot, rule)
    for skipped in r.skipped:
        doc.heading(f"{skipped.robot}: not checked")
        doc.line(Seg(skipped.reason, "yellow"), 2)
    if r.groups:
        _groups_table(doc, r.groups)
    return doc


def _groups_table(doc: Doc, groups: tuple[GroupRules, ...]) -> None:
    """Outcome and lowest robustness of each rule per robot and day."""
    doc.heading("By robot and day")
    rows: list[list[Line]] = [
        [
            g.robot,
            g.day,
            rule.rule,
            Seg(_WORDS[rule.outcome.value], _STYLE[rule.outcome.value]),
            "n/a" if rule.robustness is None else f"{rule.robustness:.4g}",
            str(rule.decidable_cycles),
            str(rule.violations),
        ]
        for g in groups
        for rule in g.rules
    ]
    doc.table(
        [
            Column("robot"),
            Column("day"),
            Column("rule"),
            Column("outcome"),
            Column("robustness", "right"),
            Column("judged", "right"),
            Column("violations", "right"),
        ],
        rows,
    )


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
    outside = {seen.signal: seen for seen in rule.seen_outside}
    for name in rule.unseen:
        seen = outside.get(name)
        note = (
            f"note: the log never shows {name} (a typo?)"
            if seen is None
            else f"note: {name} does not occur in the window; the log shows it "
            f"{clock.show(seen.first_ns)} .. {clock.show(seen.last_ns)} "
            f"(cycles {seen.first_cycle}-{seen.last_cycle})"
        )
        doc.line(Seg(note, "yellow"), 4)
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
