"""``trace-audit metrics``: the paper's auditability tables (ET, ET_partial, TC, DR, TCS).

Parses its arguments into a ``MetricsConfig``, calls ``trace_audit.metrics.compute_metrics``
(or ``index_metrics`` with ``--index``) and renders the typed report: the tables and their
notes as a ``Printout`` for people, or JSON (the report with Table II and III as the paper
names their columns) for scripts. A metric under its ``--fail-under`` threshold exits 1.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded
from trace_audit.cli.doc import BoxColumn, BoxTable, Printout
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
    from trace_audit.metrics import FailedChecks, MetricsConfig, MetricsReport, Stat

__all__ = ["metrics_command", "metrics_doc"]

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
            start_ns=_window_ns(start, logs, robot, index),
            end_ns=_window_ns(end, logs, robot, index),
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
        to_json=lambda r: _json(r, failures),
    )
    if not report.passed:
        below = ", ".join(
            f"{c.metric} {_pct(c.value)} < {c.threshold * 100:.1f}%"
            for c in report.thresholds
            if not c.passed
        )
        sys.stderr.write(f"trace-audit: below threshold: {below}\n")
        raise typer.Exit(EXIT_FINDINGS)


def _window_ns(
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


def _parse_by(value: str | None) -> Any:
    from trace_audit.metrics import GROUP_BYS

    if value is not None and value not in GROUP_BYS:
        raise UsageError(f"--by must be one of {', '.join(GROUP_BYS)}, got {value!r}")
    return value


def _from_index(
    index: Path, by: str | None, config: MetricsConfig, *, failures: bool, limits: QueryLimits
) -> MetricsReport:
    from trace_audit.fleet.query import index_metrics, parse_index_by

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


# --- the document -------------------------------------------------------------------------


def _pct(value: float | None, digits: int = 1, *, unit: bool = True) -> str:
    if value is None:
        return "n/a"
    return f"{value * 100:.{digits}f}" + ("%" if unit else "")


def _pm(stat: Stat) -> str:
    return f"{stat.mean * 100:.1f}±{stat.std * 100:.1f}"


def _share(count: int, total: int) -> str:
    return f"{count}/{total}"


_WIDE = 90
"""Console columns from which Table III shows TCS too."""


def metrics_doc(report: MetricsReport, *, failures: bool, width: int) -> Printout:
    """The metrics report for people: Table II and its notes, the execution deviation per
    channel, Table III, the failed execution checks, what was not read, the failures
    (``--failures``), the thresholds."""
    out = Printout()
    overall = report.overall
    segs = len(report.segments)
    named = len(report.robots)
    robots = f"; robot{'s' if named > 1 else ''} {', '.join(report.robots)}" if named else ""
    out.print(
        f"[bold]Auditability[/bold] of {overall.decisions} decisions in {segs} "
        f"segment{'s' if segs != 1 else ''} ({', '.join(report.logs)}{robots})"
    )
    out.table(_table_ii(report))
    _table_ii_notes(out, report)
    if report.channel_deviation:
        out.table(_channels(report))
        fewest = min(c.cycles for c in report.channel_deviation)
        if fewest < report.overall.decisions:
            out.print(
                f"  Channel figures cover the cycles that log each channel (as few as "
                f"{fewest:,} of the {report.overall.decisions:,} decisions), not every decision."
            )
    if report.groups:
        wide = width >= _WIDE
        out.table(_table_iii(report, wide=wide))
        out.print(
            "  ET std in each row is across that group's decisions; ET_p = ET_partial mean"
            + ("." if wide else "; TCS per group in --json (the terminal is too narrow).")
        )
    if report.failed_checks is not None:
        out.table(_failed_checks(report.failed_checks))
    _reading_notes(out, report)
    if failures:
        _failures(out, report)
    for check in report.thresholds:
        verdict = "ok" if check.passed else "BELOW"
        out.print(
            f"  threshold {check.metric} >= {check.threshold * 100:.1f}%: "
            f"{_pct(check.value, 2)} {verdict}"
        )
    return out


def _table_ii(report: MetricsReport) -> BoxTable:
    overall = report.overall
    names = ("Method", "ET%", "fully tr.", "TC%", "gaps", "DR%", "not rec.", "Time")
    columns = [BoxColumn(name, "left" if name == "Method" else "right") for name in names]
    columns[1] = BoxColumn("ET%", "right", min_width=len(_pm(overall.et)))
    row = (
        "TRACE (this log)",
        _pm(overall.et),
        _share(overall.fully_traceable, overall.decisions),
        _pct(overall.tc, unit=False),
        f"{overall.gaps} ({overall.gap_s:.2f} s)",
        _pct(overall.dr, unit=False),
        _share(overall.not_reconstructable, overall.decisions),
        report.logging_time,
    )
    return BoxTable(
        tuple(columns),
        (row,),
        title="Table II: auditability metrics",
        flush=True,
        collapse_plain=True,
    )


def _table_ii_notes(out: Printout, report: MetricsReport) -> None:
    """What Table II's columns mean, the spread across groups, and what ET leaves out."""
    overall = report.overall
    out.print(
        "  ET: mean ± std across decisions; fully tr.: fully traceable decisions; "
        f"gaps: count (gap time) in a {overall.window_s:.1f} s window; not rec.: not "
        "reconstructable decisions."
    )
    if report.across_groups is not None:
        a = report.across_groups
        tc = _pm(a.tc) if a.tc else "n/a"
        dr = _pm(a.dr) if a.dr else "n/a"
        out.print(
            f"  Across {a.groups} {a.by}s (mean ± std of the per-{a.by} values): "
            f"ET {_pm(a.et)}, fully traceable {_pm(a.fully_traceable_share)}, "
            f"ET_partial {a.et_partial.mean:.3f} ± {a.et_partial.std:.3f}, TC {tc}, DR {dr}."
        )
    out.print(
        f"  Fully traceable {_pm(overall.fully_traceable_share)}%, ET_partial "
        f"{overall.et_partial.mean:.3f} ± {overall.et_partial.std:.3f}, TCS "
        f"{overall.tcs.mean:.3f} ± {overall.tcs.std:.3f} (std across decisions); factors "
        f"traceable {_share(overall.factors_traceable, overall.factors)}."
    )
    if overall.summarized:
        out.print(
            f"  {overall.summarized} decisions come from warm-tier summaries, which keep the "
            "evidence refs but not the sensor readings: on those ET stops one link short "
            "by design, ET_partial still measures the chain."
        )
    if overall.no_factors:
        named = overall.decisions - overall.no_factors
        et_named = overall.et.mean * overall.decisions / named if named else None
        out.print(
            f"  {overall.no_factors} decisions name no factors (action missing or rationale "
            f"truncated away): ET(d) = 0 by definition; over the {named} that name factors, "
            f"ET {_pct(et_named)}."
        )
    _seal_note(out, report)


def _seal_note(out: Printout, report: MetricsReport) -> None:
    """Seals, integrity failures, missing and declared-dropped cycles, clock restarts."""
    overall = report.overall
    out.print(
        f"  Sealed {overall.sealed}, unsealed {overall.unsealed}, integrity failed "
        f"{overall.integrity_failed}; the gaps hold ~{overall.missing_cycles} missing cycles, "
        f"the seals declare {overall.declared_dropped} dropped"
        + (f", {overall.clock_anomalies} clock anomalies" if overall.clock_anomalies else "")
        + (
            f"; the robot's clock restarted {overall.clock_restarts} time(s) between segments "
            "(allowed; each run starts its own window)."
            if overall.clock_restarts
            else "."
        )
    )


def _channels(report: MetricsReport) -> BoxTable:
    """Execution deviation per actuator channel, in each channel's own unit."""
    names = ("channel", "unit", "cycles", "mean", "max")
    columns = tuple(
        BoxColumn(name, "left" if name in ("channel", "unit") else "right") for name in names
    )
    rows = tuple(
        (
            c.name,
            c.unit,
            str(c.cycles) if c.logged == c.cycles else f"{c.cycles} ({c.logged} with deviation)",
            "-" if c.mean is None else f"{c.mean:.4g}",
            "-" if c.max is None else f"{c.max:.4g}",
        )
        for c in report.channel_deviation
    )
    return BoxTable(columns, rows, title="Execution deviation per channel", flush=True)


def _table_iii(report: MetricsReport, *, wide: bool) -> BoxTable:
    """A row per group; TCS only when the console is wide enough."""
    names = (
        *(report.by or "group", "cycles", "ET%", "fully tr.", "ET_p", "TC%", "gaps", "DR%"),
        *("not rec.", *(("TCS",) if wide else ())),
    )
    columns = [BoxColumn(name, "left" if name == report.by else "right") for name in names]
    # The name and ET columns must not be cut; the count columns may wrap their headers.
    columns[0] = BoxColumn(
        columns[0].header, columns[0].justify, min_width=max(len(g.name) for g in report.groups)
    )
    columns[2] = BoxColumn("ET%", "right", min_width=max(len(_pm(g.et)) for g in report.groups))
    rows = tuple(
        (
            g.name,
            str(g.decisions),
            _pm(g.et),
            _share(g.fully_traceable, g.decisions),
            f"{g.et_partial.mean:.3f}",
            _pct(g.tc, unit=False),
            str(g.gaps),
            _pct(g.dr, unit=False),
            str(g.not_reconstructable),
            *((f"{g.tcs.mean:.3f}",) if wide else ()),
        )
        for g in report.groups
    )
    return BoxTable(
        tuple(columns), rows, title=f"Table III: per {report.by}", flush=True, collapse_plain=True
    )


def _failed_checks(checks: FailedChecks) -> BoxTable:
    """Failed execution checks per robot and rule: how many, and the first and the last to
    fail (a row each; one when it failed once), at times in the log's clock."""
    names = ("robot", "rule", "failed", "", "cycle", "at")
    columns = tuple(
        BoxColumn(name, "right" if name in ("failed", "cycle") else "left") for name in names
    )
    show = checks.clock.show
    rows: list[tuple[str, ...]] = []
    for r in checks.rules:
        if r.failed == 1:
            rows.append((r.robot, r.rule, "1", "only", str(r.first_cycle), show(r.first_t_ns)))
            continue
        rows.append(
            (r.robot, r.rule, str(r.failed), "first", str(r.first_cycle), show(r.first_t_ns))
        )
        rows.append(("", "", "", "last", str(r.last_cycle), show(r.last_t_ns)))
    return BoxTable(columns, tuple(rows), title="Failed execution checks", flush=True)


def _reading_notes(out: Printout, report: MetricsReport) -> None:
    """What was not read or not scored, what an index does not hold, external refs."""
    for skipped in report.skipped_segments:
        out.verbatim(f"  not read: {skipped}")
    for problem in report.unreadable:
        out.verbatim(f"  unreadable file, not scored: {problem}")
    if report.not_in_index:
        out.verbatim(
            "  not in the index: logging time, execution deviation per channel, evidence "
            "refs into external recordings, the failing decisions and gaps themselves "
            "(run metrics on the logs for them)"
        )
    if report.external_refs:
        ext = report.external_refs
        out.verbatim(
            f"  evidence refs into external recordings: {ext.get('resolved', 0)} resolved, "
            f"{ext.get('broken', 0)} broken, {ext.get('unresolved', 0)} unresolved"
            + (" (recording not given: --evidence)" if ext.get("unresolved") else "")
        )


def _failures(out: Printout, report: MetricsReport) -> None:
    """Each failing decision with what it misses, then each gap."""
    listed = len(report.failures)
    out.print(
        f"\n[bold]Failing decisions[/bold]: {report.failures_total}"
        + (f" (first {listed} listed)" if listed < report.failures_total else "")
    )
    for f in report.failures:
        out.verbatim(
            f"  cycle {f.cycle}  t={f.t_ns / 1e9:.3f} s  [{f.group}]  "
            f"ET {f.et:.2f}, ET_partial {f.et_partial:.2f}"
        )
        for problem in f.problems:
            out.verbatim(f"      {problem}")
    out.print(f"\n[bold]Gaps[/bold]: {report.gaps_total}")
    for gap in report.gaps:
        out.verbatim(
            f"  {gap.robot}: after cycle {gap.after_cycle} (t={gap.after_t_ns / 1e9:.3f} s) "
            f"until cycle {gap.before_cycle} (t={gap.before_t_ns / 1e9:.3f} s): "
            f"{gap.gap_ns / 1e9:.3f} s, ~{gap.missing_cycles} missing, "
            f"{gap.declared_dropped} declared dropped"
        )


def _json(report: MetricsReport, failures: bool) -> dict[str, Any]:
    from trace_audit.jsonout import to_jsonable

    data: dict[str, Any] = to_jsonable(report)
    data["passed"] = report.passed
    o = report.overall
    data["table_ii"] = {
        "ET_mean": o.et.mean,
        "ET_std_across_decisions": o.et.std,
        "ET_std_across_groups": report.across_groups.et.std if report.across_groups else None,
        "fully_traceable": o.fully_traceable,
        "decisions": o.decisions,
        "TC": o.tc,
        "gaps": o.gaps,
        "DR": o.dr,
        "not_reconstructable": o.not_reconstructable,
        "time_per_cycle": report.logging_time,
    }
    data["table_iii"] = [
        {
            "group": g.name,
            "decisions": g.decisions,
            "ET": g.et.mean,
            "ET_partial": g.et_partial.mean,
            "TC": g.tc,
            "DR": g.dr,
            "fully_traceable": g.fully_traceable,
            "gaps": g.gaps,
            "not_reconstructable": g.not_reconstructable,
        }
        for g in report.groups
    ]
    if not failures:
        data.pop("failures")
        data.pop("gaps")
    return data
