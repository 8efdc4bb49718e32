"""``trace-audit metrics``: the paper's auditability tables (ET, ET_partial, TC, DR, TCS).

Parses its arguments into a ``MetricsConfig``, calls ``trace_audit.metrics.compute_metrics``
(or ``index_metrics`` with ``--index``) and renders the typed report: the tables and their
notes as a ``Doc`` of console blocks for people, or JSON (the report with Table II and III
as the paper names their columns) for scripts. A metric under its ``--fail-under``
threshold exits 1.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, TypeGuard

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded
from trace_audit.cli.metrics_doc import metrics_doc, metrics_json, pct
from trace_audit.cli.options import (
    EvidencePaths,
    JsonOption,
    MemoryLimitOption,
    PlainOption,
    RobotsOption,
    SchedulerOption,
    SqlTimeoutOption,
    cluster,
    evidence_option,
    jobs_option,
    sql_limits,
)
from trace_audit.cli.output import console_width, emit, progress_bar
from trace_runtime.errors import UsageError

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from concurrent.futures import Executor

    from trace_audit.fleet.limits import QueryLimits
    from trace_audit.metrics import GroupBy, MetricsConfig, MetricsReport

__all__ = ["metrics_command", "window_ns"]

_PROGRESS_MIN_CYCLES = 20_000

_HELP = "\n\n".join(
    [
        ("Measure auditability from what was logged: the paper's Tables II and III."),
        ("[bold]Definitions[/bold] (details in docs/metrics.md):"),
        (
            "- [bold]ET(d)[/bold]: share of the decision's factors (rationale.factors of "
            "/trace/action) with a documented chain factor node -> belief edges (child to "
            "parent) -> entity node -> perception entity -> evidence ref -> a logged /sensors "
            "message the ref resolves to (topic, log time, sequence, sha256). Expected depth "
            "5 (state-node factor) or 4 (entity-node factor). No action or no factors: ET = "
            "0. Shown as mean ± std across decisions, and the number and share of fully "
            "traceable decisions."
        ),
        (
            "- [bold]ET_partial(d)[/bold]: mean over factors of documented depth / expected "
            "depth (consecutive documented levels from the factor down)."
        ),
        (
            "- [bold]TC[/bold] = 1 - sum(gaps) / window per robot. A gap is an interval "
            "between two sealed cycles longer than (1 + gap tolerance) x the nominal period "
            "(trace.session period_ns), counted as the time beyond one period; window = last "
            "- first sealed cycle + one period. The seals' dropped counts are reported as "
            "declared drops."
        ),
        (
            "- [bold]DR(d)[/bold] = action logged x at least one alternative x complete "
            "rationale (not truncated, factors present, counterfactuals present or "
            "counterfactuals_none_applicable). A sealed cycle without an action is not "
            "reconstructable."
        ),
        (
            "- [bold]TCS(d)[/bold] in [0, 1]: weighted mean of ET, ET_partial, DR, "
            "continuity and integrity (default weights 0.3/0.1/0.3/0.1/0.2), 0 when integrity "
            "fails (seal missing, a layer not matching its seal digest, or the hash chain "
            "broken)."
        ),
        (
            "Stds are population stds; each is labelled with what it is taken across. With "
            "--by, the std of the group values across groups is shown as well (the paper's "
            "footnote)."
        ),
        (
            "On a log root of several robots and no --by, each robot is a row (--robot "
            "selects robots). Failed execution checks (/trace/execution checks whose passed "
            "is false) are counted per robot and rule, with the first and last to fail."
        ),
        ("[bold]Examples[/bold]:"),
        ("  trace-audit metrics run.mcap --by scenario"),
        ("  trace-audit metrics fleet/ --by robot --json --jobs 2"),
        ("  trace-audit metrics fleet/ --robot amr-01 --robot amr-02 --by scenario"),
        ("  trace-audit metrics run.mcap --failures --fail-under ET=0.95,DR=95%"),
        ("  trace-audit metrics --index fleet-index/ --by robot,day"),
        ("  trace-audit metrics logs/ --scheduler tcp://10.0.0.5:8786 --json"),
    ]
)


# --- the command ----------------------------------------------------------------------------

_Logs = Annotated[
    list[Path] | None,
    typer.Argument(help="Log files, directories of segments, or log roots.", show_default=False),
]
_By = Annotated[
    str | None,
    typer.Option(
        "--by",
        help="Group decisions: scenario, segment, robot or hour (UTC); with --index also "
        "day, software_version, policy_version, tier, command, several comma-separated.",
    ),
]
_Index = Annotated[
    Path | None,
    typer.Option(
        "--index",
        help="Compute from a fleet index (trace-audit index) instead of the logs.",
        show_default=False,
    ),
]
_Failures = Annotated[
    bool,
    typer.Option("--failures", help="List each failing decision and gap, and what is missing."),
]
_FailUnder = Annotated[
    str | None,
    typer.Option(
        "--fail-under",
        help="Exit 1 when a metric is below its threshold, e.g. ET=0.95,DR=95%. "
        "Metrics: ET, ET_full, ET_partial, TC, DR, TCS.",
    ),
]
_GapTolerance = Annotated[
    float,
    typer.Option(
        "--gap-tolerance",
        help="Periods of lateness tolerated before an interval counts as a gap.",
        min=0.0,
    ),
]
_SensorWindow = Annotated[
    int,
    typer.Option(
        "--sensor-window",
        help="Cycles before a decision whose sensor messages its refs may resolve to.",
        min=0,
    ),
]
_Start = Annotated[
    str | None,
    typer.Option(
        "--start",
        help="Analysis window start (t1): seconds in the log's clock, +seconds after the "
        "log start, or on a wall clock an ISO 8601 time.",
        show_default=False,
        metavar="TIME",
    ),
]
_End = Annotated[
    str | None,
    typer.Option(
        "--end",
        help="Analysis window end (t2), in the same forms.",
        show_default=False,
        metavar="TIME",
    ),
]
_TcsWeights = Annotated[
    str | None,
    typer.Option(
        "--tcs-weights",
        help="TCS weights and gate, e.g. et=0.4,dr=0.4,gate=off (keys: et, et_partial, "
        "dr, continuity, integrity, gate).",
    ),
]


@app.command("metrics", help=_HELP)
def metrics_command(
    logs: _Logs = None,
    *,
    robot: RobotsOption = None,
    by: _By = None,
    index: _Index = None,
    scheduler: SchedulerOption = None,
    failures: _Failures = False,
    fail_under: _FailUnder = None,
    jobs: Annotated[int, jobs_option("Processes to spread segments over.")] = 1,
    gap_tolerance: _GapTolerance = 0.5,
    sensor_window: _SensorWindow = 50,
    start: _Start = None,
    end: _End = None,
    tcs_weights: _TcsWeights = None,
    evidence: Annotated[EvidencePaths, evidence_option("the logs' evidence refs")] = None,
    memory_limit: MemoryLimitOption = None,
    timeout: SqlTimeoutOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    def run() -> MetricsReport:
        from trace_audit.metrics import MetricsConfig, TCSWeights, parse_thresholds

        if (index is None) == (not logs):
            raise UsageError("give either logs or --index INDEX")
        config = MetricsConfig(
            by=None if index is not None else _parse_by(by),
            gap_tolerance=gap_tolerance,
            sensor_window=sensor_window,
            weights=TCSWeights.parse(tcs_weights) if tcs_weights else TCSWeights(),
            thresholds=parse_thresholds(fail_under) if fail_under else {},
            workers=jobs,
            start_ns=window_ns(start, logs, robot, index),
            end_ns=window_ns(end, logs, robot, index),
            max_listed=10_000 if failures else 0,
            evidence=tuple(str(p) for p in evidence or ()),
        )
        if index is not None:
            if robot:
                raise UsageError("--robot is not supported with --index (use --by robot)")
            limits = sql_limits(memory_limit, timeout)
            return _from_index(index, by, config, failures=failures, limits=limits)
        if memory_limit is not None or timeout is not None:
            raise UsageError("--memory-limit and --timeout bound the SQL of --index only")
        with cluster(scheduler) as executor:
            return _with_progress(
                logs or [], config, robots=robot, quiet=json_out or plain, executor=executor
            )

    report = guarded(run)
    emit(
        report,
        lambda r: metrics_doc(r, failures=failures, width=console_width(plain)),
        json_out=json_out,
        plain=plain,
        to_json=lambda r: metrics_json(r, failures),
    )
    _exit_when_below(report)


def _exit_when_below(report: MetricsReport) -> None:
    """Exit 1, naming each metric under its ``--fail-under`` threshold, when any is."""
    if report.passed:
        return
    below = ", ".join(
        f"{c.metric} {pct(c.value)} < {c.threshold * 100:.1f}%"
        for c in report.thresholds
        if not c.passed
    )
    sys.stderr.write(f"trace-audit: below threshold: {below}\n")
    raise typer.Exit(EXIT_FINDINGS)


def window_ns(
    text: str | None, logs: list[Path] | None, robots: list[str] | None, index: Path | None
) -> int | None:
    """A window end as ``t_ns``: seconds are read exactly as given; ``+seconds`` and ISO
    times need the log (its start, its clock), which is opened for them alone. The window
    is one for every robot scored, so ``+seconds`` (each robot's own start) needs one robot,
    and an ISO time robots on a wall clock."""
    if text is None:
        return None
    from trace_audit.log_time import LogClock, NotWallClockError, TimePoint, resolve_time

    point = TimePoint.parse(text)
    if index is not None or not (point.relative or point.wall):
        return point.ns  # with --index, index_metrics refuses any window (its own rule)
    from trace_audit.selection import Selection, each_robot
    from trace_runtime.reading.logset import open_logs

    log = Selection(tuple(robots or ())).of(open_logs(logs or []))
    if point.relative and len(log.robots) > 1:
        raise UsageError(
            f"{text!r} counts from each robot's own start, and this log holds "
            f"{len(log.robots)} robots: choose one with --robot, or give seconds"
        )
    if point.wall:
        unclocked = [r.first_robot for r in each_robot(log) if not LogClock.of(r).wall]
        if unclocked:
            raise NotWallClockError(
                f"{text!r} is a time of day, and {', '.join(unclocked)} keep(s) no wall "
                "clock: choose robots with --robot, or give seconds"
            )
    return resolve_time(point, log)


def _parse_by(value: str | None) -> GroupBy | None:
    from trace_audit.metrics import GROUP_BYS

    if value is not None and not _is_group_by(value):
        raise UsageError(f"--by must be one of {', '.join(GROUP_BYS)}, got {value!r}")
    return value


def _is_group_by(value: str) -> TypeGuard[GroupBy]:
    from trace_audit.metrics import GROUP_BYS

    return value in GROUP_BYS


def _from_index(
    index: Path, by: str | None, config: MetricsConfig, *, failures: bool, limits: QueryLimits
) -> MetricsReport:
    from trace_audit.fleet.metrics import index_metrics, parse_index_by

    if failures:  # the index counts them; what each one misses is in the logs
        raise UsageError(
            "--failures is not supported with --index (run metrics on the logs, or "
            "trace-audit find INDEX --where 'NOT d.dr' for the rows)"
        )
    return index_metrics(index, parse_index_by(by), config, limits)


def _with_progress(
    logs: list[Path],
    config: MetricsConfig,
    *,
    robots: list[str] | None,
    quiet: bool,
    executor: Executor | None,
) -> MetricsReport:
    from trace_audit.metrics import compute_metrics

    if quiet or not sys.stderr.isatty():
        return compute_metrics(logs, config, robots=robots, executor=executor)
    with progress_bar("scoring cycles", visible=False) as bar:
        task = bar.task_ids[0]

        def progress(done: int, expected: int | None) -> None:
            visible = expected is None or expected >= _PROGRESS_MIN_CYCLES
            bar.update(task, completed=done, total=expected, visible=visible)

        return compute_metrics(logs, config, robots=robots, progress=progress, executor=executor)
