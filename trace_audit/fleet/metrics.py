"""``metrics --index``: ET, ET_partial, TC, DR and TCS of a fleet from its index's decision
rows, summed by DuckDB, without re-reading the logs; what the index can answer (the same
gap tolerance and sensor window it was built with) and what it may be grouped by."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from trace_audit.fleet.folder import load_manifest
from trace_audit.fleet.limits import QueryLimits
from trace_audit.fleet.query import run_query
from trace_audit.metrics import (
    NO_SCENARIO,
    GroupSums,
    MetricsConfig,
    MetricsReport,
    report_from_sums,
)
from trace_runtime.errors import LogReadError, UsageError

__all__ = ["DAY_MEANING", "INDEX_GROUP_BYS", "index_metrics", "parse_index_by"]

INDEX_GROUP_BYS: dict[str, str] = {
    "robot": "robot",
    "day": "CAST(day AS VARCHAR)",
    "hour": "hour",
    "segment": "segment",
    "scenario": f"COALESCE(scenario, '{NO_SCENARIO}')",
    "software_version": "software_version",
    "policy_version": "policy_version",
    "tier": "tier",
    "command": "command",
}
"""What ``metrics --index --by`` may group by (comma-separated for several), as SQL."""

DAY_MEANING = (
    "the UTC date (YYYY-MM-DD) of the decision's time on a wall clock; on a sim or "
    "monotonic clock, whose times count from an arbitrary zero, the robot's run: "
    "run-<number of the run's first segment>"
)
"""What the index's ``day`` column (and ``metrics --index --by day``) means."""


def parse_index_by(text: str | None) -> list[str]:
    """``robot,day`` -> ["robot", "day"]; ``UsageError`` naming what is allowed."""
    if not text:
        return []
    keys = [k.strip() for k in text.split(",") if k.strip()]
    for key in keys:
        if key not in INDEX_GROUP_BYS:
            raise UsageError(
                f"cannot group the index by {key!r} (use {', '.join(INDEX_GROUP_BYS)})"
            )
    return keys


def index_metrics(
    index: str | Path,
    by: Sequence[str] = (),
    config: MetricsConfig | None = None,
    limits: QueryLimits | None = None,
) -> MetricsReport:
    """ET, ET_partial, TC, DR and TCS from the index's decision rows, without reading a log:
    the sums metrics keeps per group, summed again by DuckDB (``report_from_sums``). As
    ``compute_metrics`` does, an index of several robots and no ``by`` is grouped by robot."""
    started = time.perf_counter()
    cfg = config or MetricsConfig()
    robots = _check_index_config(index, cfg, by)
    if not by and len(robots) > 1:
        by = ["robot"]
    result = run_query(index, _sums_sql(cfg, by), limits=limits)
    groups: dict[str, GroupSums] = {}
    segments: set[str] = set()
    cycles = failures_total = 0
    for row in result.rows:
        name, sums, names, failing = _group_sums(row)
        failures_total += failing
        groups[name] = sums
        segments.update(names)
        cycles += sums.decisions
    report = report_from_sums(
        [str(index)],
        cfg,
        groups,
        by=",".join(by) or None,
        segments=tuple(sorted(segments)),
        cycles=cycles,
        elapsed=time.perf_counter() - started,
    )
    # Counted from the rows as the logs count them; the listing itself stays with the logs.
    gaps_total = sum(g.gaps for g in groups.values())
    definitions = dict(report.definitions)
    if "day" in by:
        definitions["day"] = DAY_MEANING
    return dataclasses.replace(
        report,
        definitions=definitions,
        failures_total=failures_total,
        gaps_total=gaps_total,
        logging_time="not in the index",
        not_in_index=("logging_cost", "channel_deviation", "external_refs", "failures", "gaps"),
    )


def _check_index_config(index: str | Path, cfg: MetricsConfig, by: Sequence[str]) -> set[str]:
    """``UsageError`` (``LogReadError`` for no index) unless the index can answer with ``cfg``:
    built with the same gap tolerance and sensor window, no time window, no evidence. The
    robots the index holds."""
    manifest = load_manifest(index)
    if manifest is None:
        raise LogReadError(str(index), "not a fleet index (run trace-audit index first)")
    built = manifest.get("config", {})
    for name in ("gap_tolerance", "sensor_window"):
        if built.get(name) != getattr(cfg, name):
            raise UsageError(
                f"the index was built with {name} {built.get(name)}, not "
                f"{getattr(cfg, name)}: rebuild it or drop the option"
            )
    if cfg.start_ns is not None or cfg.end_ns is not None:
        raise UsageError("--start/--end are not supported with --index (filter in SQL)")
    for key in by:
        if key not in INDEX_GROUP_BYS:
            raise UsageError(f"cannot group the index by {key!r}")
    if cfg.evidence:
        raise UsageError("--evidence is not supported with --index (run metrics on the logs)")
    entries = manifest.get("segments")
    return {
        str(e.get("robot"))
        for e in (entries.values() if isinstance(entries, dict) else ())
        if isinstance(e, dict)
    }


def _sums_sql(cfg: MetricsConfig, by: Sequence[str]) -> str:
    """The query summing each group's decision rows into the columns of ``GroupSums``; its
    TCS is recomputed from the rows with ``cfg``'s weights (``trust_score`` as SQL)."""
    group = " || ', ' || ".join(f"CAST({INDEX_GROUP_BYS[k]} AS VARCHAR)" for k in by) or "'all'"
    w = cfg.weights
    total = w.et + w.et_partial + w.dr + w.continuity + w.integrity
    gate = "NOT seal_verified" if w.integrity_gate else "false"
    # A decision whose ET is unknown (null) has TCS unknown too; the sums skip nulls.
    tcs = (
        f"CASE WHEN et IS NULL THEN NULL WHEN {gate} THEN 0.0 ELSE "
        f"({w.et!r} * et + {w.et_partial!r} * et_partial + "
        f"{w.dr!r} * dr::DOUBLE + {w.continuity!r} * continuity + "
        f"{w.integrity!r} * seal_verified::DOUBLE) / {total!r} END"
    )
    return f"""
        WITH d AS (SELECT *, {group} AS g, {tcs} AS tcs_w FROM decisions)
        SELECT g, count(*), sum(sealed::INT), sum(summarized::INT),
               fsum(et), fsum(et * et), fsum(et_partial), fsum(et_partial * et_partial),
               sum((et IS NOT NULL AND factors_total > 0
                   AND factors_traceable = factors_total)::INT),
               sum(factors_total) FILTER (WHERE et IS NOT NULL),
               sum(factors_traceable) FILTER (WHERE et IS NOT NULL),
               sum((et IS NOT NULL AND factors_total = 0)::INT),
               sum(dr::INT), sum(seal_verified::INT), fsum(tcs_w), fsum(tcs_w * tcs_w),
               sum(window_ns), sum(gap_ns), sum((gap_ns > 0)::INT), sum(missing_cycles),
               sum(dropped), sum(clock_anomaly::INT), list(DISTINCT segment),
               count(*) FILTER (WHERE NOT ((et IS NULL OR (factors_total > 0
                   AND factors_traceable = factors_total)) AND dr AND seal_verified)),
               count(*) FILTER (WHERE et IS NULL)
        FROM d GROUP BY g ORDER BY g
    """


def _group_sums(row: Sequence[Any]) -> tuple[str, GroupSums, list[str], int]:
    """One row of ``_sums_sql``: (group, its sums, its segments, its failing decisions)."""
    (name, n, sealed, summarized, et, et2, etp, etp2, full, factors, traceable) = row[:11]
    (no_factors, dr, intact, tcs_sum, tcs2, window, gap, gaps, missing) = row[11:20]
    (dropped, anomalies, names, failing, unknown) = row[20:]
    sums = GroupSums(
        decisions=n,
        sealed=sealed,
        summarized=summarized,
        et_sum=et or 0.0,  # fsum over no known row is NULL
        et_sq=et2 or 0.0,
        etp_sum=etp or 0.0,
        etp_sq=etp2 or 0.0,
        full=full,
        factors=factors or 0,
        factors_traceable=traceable or 0,
        no_factors=no_factors,
        dr_ok=dr,
        integrity_ok=intact,
        tcs_sum=tcs_sum or 0.0,
        tcs_sq=tcs2 or 0.0,
        window_ns=int(window),
        gap_ns=int(gap),
        gaps=gaps,
        missing_cycles=int(missing),
        dropped=int(dropped),
        anomalies=anomalies,
        unknown=unknown,
    )
    return str(name), sums, names, failing
