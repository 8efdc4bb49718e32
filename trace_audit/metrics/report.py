"""From the sums of a scan (or of the fleet index's rows) to a ``MetricsReport``.

Means and population stds per group and across groups, threshold checks, the logger's own
cost and the execution channels' deviation, and the definitions the report shows.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from trace_audit.chains import EXPECTED_DEPTH_ENTITY, EXPECTED_DEPTH_STATE
from trace_audit.log_time import LogClock
from trace_audit.metrics.config import MetricsConfig
from trace_audit.metrics.results import (
    AcrossGroups,
    ChannelDeviation,
    FailedChecks,
    GroupMetrics,
    LoggingCost,
    MetricsReport,
    RuleFailures,
    Stat,
    ThresholdCheck,
)
from trace_audit.metrics.sums import CheckTally, GroupSums, ScanResult
from trace_runtime.costs import TIMING_METADATA, CostHistogram
from trace_runtime.errors import LogReadError
from trace_runtime.reading.logset import Log

__all__ = ["build_report", "report_from_sums"]


def report_from_sums(
    sources: Sequence[str],
    cfg: MetricsConfig,
    groups: Mapping[str, GroupSums],
    *,
    by: str | None,
    segments: tuple[str, ...],
    cycles: int,
    elapsed: float,
) -> MetricsReport:
    """A report from sums gathered elsewhere (the fleet index's decision rows): the same
    tables, stds and thresholds as a scan of the logs; nothing listed, timing not logged.
    ``by`` names the grouping of ``groups`` (any label: the index groups by more keys)."""
    total = ScanResult(groups=dict(groups), cycles=cycles)
    report = build_report(
        sources, cfg, log=None, total=total, segments=segments, elapsed=elapsed, by=by
    )
    if report.overall.decisions == 0:
        raise LogReadError(str(sources[0]) if sources else "index", "no decisions selected")
    return report


def build_report(
    paths: Sequence[str | Path],
    cfg: MetricsConfig,
    *,
    log: Log | None,
    total: ScanResult,
    segments: tuple[str, ...],
    elapsed: float,
    by: str | None,
    robots: Sequence[str] = (),
) -> MetricsReport:
    """The report of ``paths`` from what scanning them produced (``total``); ``log`` names
    the copies not read and the files that could not be, and the clock of their times (None:
    the sums came from elsewhere). ``robots``: the robots asked for (empty: all)."""
    overall_acc = GroupSums()
    for acc in total.groups.values():
        overall_acc.merge(acc)
    overall = _group("all", overall_acc)
    groups: tuple[GroupMetrics, ...] = ()
    across: AcrossGroups | None = None
    if by is not None:
        groups = tuple(_group(name, acc) for name, acc in total.groups.items())
        across = _across(by, groups)
    checks = tuple(_check(name, threshold, overall) for name, threshold in cfg.thresholds.items())
    failures = tuple(sorted(total.failures, key=lambda f: (f.t_ns, f.cycle)))
    gaps = tuple(sorted(total.gaps, key=lambda g: (g.after_t_ns, g.robot)))
    cost = _logging_cost(total.timing)
    return MetricsReport(
        logs=tuple(str(p) for p in paths),
        segments=segments,
        skipped_segments=tuple(_shadowed(log)) if log is not None else (),
        unreadable=tuple(f"{p.path}: {p.reason}" for p in log.problems) if log else (),
        by=by,
        definitions=_definitions(cfg),
        overall=overall,
        groups=groups,
        across_groups=across,
        logging_time=_timing(cost),
        failures=failures,
        failures_total=total.failures_total,
        gaps=gaps,
        gaps_total=total.gaps_total,
        thresholds=checks,
        elapsed_s=elapsed,
        logging_cost=cost,
        channel_deviation=_channel_deviation(total.channels),
        cycles_per_s=total.cycles / elapsed if elapsed > 0 else 0.0,
        failed_checks=_failed_checks(total.checks, log) if total.checks and log else None,
        robots=tuple(robots),
        external_refs=dict(sorted(total.external.items())),
        unread_recordings=tuple(why for _name, why in sorted(total.unread.items())),
        clock=LogClock.of(log) if log is not None else None,
    )


def _stat(total: float, squares: float, n: int, across: str) -> Stat:
    if n == 0:  # nothing known to average: unknown, not 0
        return Stat(None, None, 0, across)
    mean = total / n
    return Stat(mean, math.sqrt(max(0.0, squares / n - mean * mean)), n, across)


def _group(name: str, acc: GroupSums) -> GroupMetrics:
    n = acc.decisions
    known = n - acc.unknown  # ET, ET_partial and TCS are over the decisions whose ET is known
    return GroupMetrics(
        name=name,
        decisions=n,
        sealed=acc.sealed,
        unsealed=n - acc.sealed,
        summarized=acc.summarized,
        et=_stat(acc.et_sum, acc.et_sq, known, "decisions"),
        fully_traceable=acc.full,
        fully_traceable_share=_stat(acc.full, acc.full, known, "decisions"),
        et_partial=_stat(acc.etp_sum, acc.etp_sq, known, "decisions"),
        factors=acc.factors,
        factors_traceable=acc.factors_traceable,
        no_factors=acc.no_factors,
        dr=acc.dr_ok / n if n else None,
        reconstructable=acc.dr_ok,
        not_reconstructable=n - acc.dr_ok,
        tc=1.0 - acc.gap_ns / acc.window_ns if acc.window_ns > 0 else None,
        window_s=acc.window_ns / 1e9,
        gap_s=acc.gap_ns / 1e9,
        gaps=acc.gaps,
        missing_cycles=acc.missing_cycles,
        declared_dropped=acc.dropped,
        clock_anomalies=acc.anomalies,
        integrity_ok=acc.integrity_ok,
        integrity_failed=n - acc.integrity_ok,
        tcs=_stat(acc.tcs_sum, acc.tcs_sq, known, "decisions"),
        unknown=acc.unknown,
        clock_restarts=acc.restarts or None,
    )


def _spread(values: Iterable[float | None], across: str) -> Stat | None:
    present = [v for v in values if v is not None]
    if not present:
        return None
    mean = sum(present) / len(present)
    var = sum((v - mean) ** 2 for v in present) / len(present)
    return Stat(mean, math.sqrt(var), len(present), across)


def _across(by: str, groups: Sequence[GroupMetrics]) -> AcrossGroups:
    label = f"{by}s"
    et = _spread((g.et.mean for g in groups), label)
    full = _spread((g.fully_traceable_share.mean for g in groups), label)
    etp = _spread((g.et_partial.mean for g in groups), label)
    empty = Stat(None, None, 0, label)
    return AcrossGroups(
        by=by,
        groups=len(groups),
        et=et or empty,
        fully_traceable_share=full or empty,
        et_partial=etp or empty,
        tc=_spread((g.tc for g in groups), label),
        dr=_spread((g.dr for g in groups), label),
    )


def _metric_value(name: str, g: GroupMetrics) -> float | None:
    if g.decisions == 0 and name != "TC":
        return None
    return {
        "ET": g.et.mean,
        "ET_full": g.fully_traceable_share.mean,
        "ET_partial": g.et_partial.mean,
        "TC": g.tc,
        "DR": g.dr,
        "TCS": g.tcs.mean,
    }[name]


def _check(name: str, threshold: float, overall: GroupMetrics) -> ThresholdCheck:
    value = _metric_value(name, overall)
    # A metric that cannot be computed (no decisions, no interval) does not pass a threshold.
    return ThresholdCheck(name, threshold, value, value is not None and value >= threshold)


def _channel_deviation(
    channels: dict[tuple[str, str], list[float]],
) -> tuple[ChannelDeviation, ...]:
    return tuple(
        ChannelDeviation(
            name=name,
            unit=unit,
            cycles=int(n),
            logged=int(logged),
            mean=total / logged if logged else None,
            max=top if logged else None,
        )
        for (name, unit), (n, logged, total, top) in sorted(channels.items())
    )


def _failed_checks(checks: Mapping[tuple[str, str], CheckTally], log: Log) -> FailedChecks:
    return FailedChecks(
        clock=LogClock.of(log),
        rules=tuple(
            RuleFailures(
                robot=robot,
                rule=rule,
                failed=tally.failed,
                first_t_ns=tally.first_t_ns,
                first_cycle=tally.first_cycle,
                last_t_ns=tally.last_t_ns,
                last_cycle=tally.last_cycle,
            )
            for (robot, rule), tally in sorted(checks.items())
        ),
    )


def _logging_cost(entries: list[tuple[float, int, CostHistogram | None]]) -> LoggingCost | None:
    weight = sum(n for _, n, _ in entries)
    if not entries or weight <= 0:
        return None
    mean_ns = sum(m * n for m, n, _ in entries) / weight
    merged: CostHistogram | None = CostHistogram()
    for _, _, histogram in entries:
        if histogram is None or merged is None:
            merged = None  # percentiles of some segments would not describe the others
        else:
            merged.merge(histogram)
    return LoggingCost(
        cycles=weight,
        segments=len(entries),
        mean_ns=mean_ns,
        p50_ns=merged.percentile_ns(0.5) if merged else None,
        p99_ns=merged.percentile_ns(0.99) if merged else None,
        max_ns=merged.max_ns if merged else None,
    )


def _timing(cost: LoggingCost | None) -> str:
    if cost is None:
        return "not logged"
    text = f"{cost.mean_ns / 1e6:.3f} ms mean per cycle"
    if cost.p50_ns is not None and cost.p99_ns is not None:
        text += f", p50 {cost.p50_ns / 1e6:.3f} ms, p99 {cost.p99_ns / 1e6:.3f} ms"
    return f"{text} ({TIMING_METADATA} metadata, {cost.cycles} cycles)"


def _definitions(cfg: MetricsConfig) -> dict[str, str]:
    w = cfg.weights
    return {
        "decision": "every cycle in the log (sealed, or an unsealed tail of a crashed writer)",
        "ET": "share of the action's factors with a documented chain to a resolving sensor "
        "reading; 0 when the action or its factors are missing; unknown (null, not 0) when "
        "a chain stops at a reading in an external recording that could not be read: such "
        "decisions are counted apart (unknown) and left out of ET, ET_partial and TCS",
        "chain": "factor node -> belief path (edges child->parent) -> entity node -> "
        "perception entity -> evidence ref -> logged sensor message",
        "expected_depth": f"{EXPECTED_DEPTH_STATE} for a factor on a derived-state node, "
        f"{EXPECTED_DEPTH_ENTITY} for a factor on an entity node",
        "ET_partial": "mean over factors of documented depth / expected depth",
        "sensor_window": f"refs resolve against the decision's cycle and the "
        f"{cfg.sensor_window} cycles before it (topic, log time, sequence, "
        "sha256)",
        "TC": f"1 - sum(gaps) / window per robot; a gap is an interval between sealed cycles "
        f"longer than (1 + {cfg.gap_tolerance:g}) x the nominal period, counted as the "
        "time beyond one period; window = last - first sealed time + one period",
        "DR": "action logged x >= 1 alternative logged x rationale complete (not truncated, "
        "factors present, counterfactuals present or none-applicable)",
        "integrity": "sealed, every layer matches its seal digest, no named layer missing, "
        "seal prev = digest of the previous seal",
        "TCS": f"({w.et:g} ET + {w.et_partial:g} ET_partial + {w.dr:g} DR + "
        f"{w.continuity:g} continuity + {w.integrity:g} integrity) / "
        f"{w.et + w.et_partial + w.dr + w.continuity + w.integrity:g}"
        + ("; 0 when integrity fails" if w.integrity_gate else ""),
        "std": "population std (ddof=0); each value says whether it is across decisions or "
        "across groups",
    }


def _shadowed(log: Log) -> list[str]:
    """Each copy of a segment not read, and the copy that is read in its place."""
    out: list[str] = []
    for copy in log.shadowed:
        key = (copy.session.robot_id, copy.session.segment, copy.session.first_cycle)
        read = next(
            (
                s
                for s in log.segments
                if (s.session.robot_id, s.session.segment, s.session.first_cycle) == key
            ),
            None,
        )
        where = ", which is read" if read is None else f" {read.path}, which is read"
        out.append(f"{copy.path} (a copy of the same segment as{where})")
    return out
