"""What ``trace-audit metrics`` prints: the paper's Tables II and III and their notes as a
``Doc`` of console blocks (rich's layout, in both modes), and the JSON for scripts (the
report: the paper's Table II and III columns, titled by what they show of the log)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_audit.cli.doc import BoxColumn, BoxTable, Doc

if TYPE_CHECKING:
    from trace_audit.cli.output import JsonValue
    from trace_audit.metrics import FailedChecks, MetricsReport, Stat

__all__ = ["metrics_doc", "metrics_json", "pct"]


def pct(value: float | None, digits: int = 1, *, unit: bool = True) -> str:
    if value is None:
        return "n/a"
    return f"{value * 100:.{digits}f}" + ("%" if unit else "")


def _pm(stat: Stat) -> str:
    """``mean±std`` in percent; ``?`` when nothing is known (never 0)."""
    if stat.mean is None or stat.std is None:
        return "?"
    return f"{stat.mean * 100:.1f}±{stat.std * 100:.1f}"


def _num(value: float | None, spec: str = ".3f") -> str:
    """A number as people read it; ``?`` when it is unknown."""
    return "?" if value is None else format(value, spec)


def _mean_std(stat: Stat) -> str:
    return "?" if stat.mean is None else f"{_num(stat.mean)} ± {_num(stat.std)}"


def _share(count: int, total: int) -> str:
    return f"{count}/{total}"


_WIDE = 90
"""Console columns from which Table III shows TCS too."""


def metrics_doc(report: MetricsReport, *, failures: bool, width: int) -> Doc:
    """The metrics report for people: Table II and its notes, the execution deviation per
    channel, Table III, the failed execution checks, what was not read, the failures
    (``--failures``), the thresholds."""
    out = Doc()
    overall = report.overall
    segs = len(report.segments)
    named = len(report.robots)
    robots = f"; robot{'s' if named > 1 else ''} {', '.join(report.robots)}" if named else ""
    out.markup(
        f"[bold]Auditability[/bold] of {overall.decisions} decisions in {segs} "
        f"segment{'s' if segs != 1 else ''} ({', '.join(report.logs)}{robots})"
    )
    out.box(_table_ii(report))
    _table_ii_notes(out, report)
    if report.channel_deviation:
        out.box(_channels(report))
        fewest = min(c.cycles for c in report.channel_deviation)
        if fewest < report.overall.decisions:
            out.markup(
                f"  Channel figures cover the cycles that log each channel (as few as "
                f"{fewest:,} of the {report.overall.decisions:,} decisions), not every decision."
            )
    if report.groups:
        wide = width >= _WIDE
        out.box(_table_iii(report, wide=wide))
        out.markup(
            "  ET std in each row is across that group's decisions; ET_p = ET_partial mean"
            + ("." if wide else "; TCS per group in --json (the terminal is too narrow).")
        )
    if report.failed_checks is not None:
        out.box(_failed_checks(report.failed_checks))
    _reading_notes(out, report)
    if failures:
        _failures(out, report)
    for check in report.thresholds:
        verdict = "ok" if check.passed else "BELOW"
        out.markup(
            f"  threshold {check.metric} >= {check.threshold * 100:.1f}%: "
            f"{pct(check.value, 2)} {verdict}"
        )
    return out


def _table_ii(report: MetricsReport) -> BoxTable:
    overall = report.overall
    # What the user's own log shows, one row: the columns are the paper's Table II's
    # (docs/metrics.md), without its comparison of methods.
    names = ("ET%", "fully tr.", "TC%", "gaps", "DR%", "not rec.", "Time")
    columns = [BoxColumn(name, "right") for name in names]
    columns[0] = BoxColumn("ET%", "right", min_width=len(_pm(overall.et)))
    row = (
        _pm(overall.et),
        _share(overall.fully_traceable, overall.decisions),
        pct(overall.tc, unit=False),
        f"{overall.gaps} ({overall.gap_s:.2f} s)",
        pct(overall.dr, unit=False),
        _share(overall.not_reconstructable, overall.decisions),
        report.logging_time,
    )
    return BoxTable(
        tuple(columns),
        (row,),
        title=f"Auditability metrics of the {overall.decisions:,} decisions",
        flush=True,
        collapse_plain=True,
    )


def _table_ii_notes(out: Doc, report: MetricsReport) -> None:
    """What Table II's columns mean, the spread across groups, and what ET leaves out."""
    overall = report.overall
    out.markup(
        "  ET: mean ± std across decisions; fully tr.: fully traceable decisions; "
        f"gaps: count (gap time) in a {overall.window_s:.1f} s window; not rec.: not "
        "reconstructable decisions."
    )
    if report.across_groups is not None:
        a = report.across_groups
        tc = _pm(a.tc) if a.tc else "n/a"
        dr = _pm(a.dr) if a.dr else "n/a"
        out.markup(
            f"  Across {a.groups} {a.by}s (mean ± std of the per-{a.by} values): "
            f"ET {_pm(a.et)}, fully traceable {_pm(a.fully_traceable_share)}, "
            f"ET_partial {_mean_std(a.et_partial)}, TC {tc}, DR {dr}."
        )
    out.markup(
        f"  Fully traceable {_pm(overall.fully_traceable_share)}%, ET_partial "
        f"{_mean_std(overall.et_partial)}, TCS {_mean_std(overall.tcs)} (std across "
        f"decisions); factors traceable {_share(overall.factors_traceable, overall.factors)}."
    )
    if overall.unknown:
        why = "; ".join(report.unread_recordings) or "a recording could not be read"
        out.verbatim(
            f"  ET {pct(overall.et.mean)} of {overall.decisions:,} decisions; "
            f"{overall.unknown:,} unknown ({why}): their ET, ET_partial and TCS are not "
            "known, so they are left out of those figures, not counted as 0."
        )
    if overall.summarized:
        out.markup(
            f"  {overall.summarized} decisions come from warm-tier summaries, which keep the "
            "evidence refs but not the sensor readings: on those ET stops one link short "
            "by design, ET_partial still measures the chain."
        )
    if overall.no_factors:
        known = overall.decisions - overall.unknown
        named = known - overall.no_factors
        mean = overall.et.mean
        et_named = mean * known / named if named and mean is not None else None
        out.markup(
            f"  {overall.no_factors} decisions name no factors (action missing or rationale "
            f"truncated away): ET(d) = 0 by definition; over the {named} that name factors, "
            f"ET {pct(et_named)}."
        )
    _seal_note(out, report)


def _seal_note(out: Doc, report: MetricsReport) -> None:
    """Seals, integrity failures, missing and declared-dropped cycles, clock restarts."""
    overall = report.overall
    out.markup(
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
            _num(g.et_partial.mean),
            pct(g.tc, unit=False),
            str(g.gaps),
            pct(g.dr, unit=False),
            str(g.not_reconstructable),
            *((_num(g.tcs.mean),) if wide else ()),
        )
        for g in report.groups
    )
    return BoxTable(tuple(columns), rows, title=f"Per {report.by}", flush=True, collapse_plain=True)


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


def _reading_notes(out: Doc, report: MetricsReport) -> None:
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
            + (" (not read: see unknown above)" if ext.get("unresolved") else "")
        )


def _failures(out: Doc, report: MetricsReport) -> None:
    """Each failing decision with what it misses, then each gap."""
    listed = len(report.failures)
    out.markup(
        f"\n[bold]Failing decisions[/bold]: {report.failures_total}"
        + (f" (first {listed} listed)" if listed < report.failures_total else "")
    )
    from trace_audit.log_time import SECONDS_CLOCK  # the library, not at --help time

    show = (report.clock or SECONDS_CLOCK).show
    for f in report.failures:
        out.verbatim(
            f"  cycle {f.cycle}  t={show(f.t_ns)}  [{f.group}]  "
            f"ET {_num(f.et, '.2f')}, ET_partial {_num(f.et_partial, '.2f')}"
        )
        for problem in f.problems:
            out.verbatim(f"      {problem}")
    out.markup(f"\n[bold]Gaps[/bold]: {report.gaps_total}")
    for gap in report.gaps:
        out.verbatim(
            f"  {gap.robot}: after cycle {gap.after_cycle} (t={show(gap.after_t_ns)}) "
            f"until cycle {gap.before_cycle} (t={show(gap.before_t_ns)}): "
            f"{gap.gap_ns / 1e9:.3f} s, ~{gap.missing_cycles} missing, "
            f"{gap.declared_dropped} declared dropped"
        )


def metrics_json(report: MetricsReport, failures: bool) -> dict[str, JsonValue]:
    from trace_audit.jsonout import to_jsonable

    data: dict[str, JsonValue] = to_jsonable(report)
    data.pop("clock", None)  # times stay t_ns in the log's clock for scripts
    data["passed"] = report.passed
    o = report.overall
    data["table_ii"] = {
        "ET_mean": o.et.mean,
        "unknown": o.unknown,
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
