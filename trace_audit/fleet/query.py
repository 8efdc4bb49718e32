"""SQL over the fleet index on DuckDB (embedded, no server), and what is built on it:
named questions (``find_decisions``) and fleet metrics without re-reading the logs.

The tables are views over the Parquet files (Hive partitions ``robot`` and ``day`` come back
as columns; ``day`` is text: the UTC date on a wall clock, ``run-<segment>`` on a sim or
monotonic clock). ``decisions`` gains ``explain``: the exact ``trace-audit explain`` command
that reconstructs the row's decision from its segment, by cycle and robot.
"""

from __future__ import annotations

import dataclasses
import datetime
import decimal
import math
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trace_audit.fleet.folder import listed_files, load_manifest
from trace_audit.fleet.limits import QueryLimits, format_size, over_limit, row_bytes, watchdog
from trace_audit.fleet.tables import TABLES, schema
from trace_audit.metrics import (
    NO_SCENARIO,
    GroupSums,
    MetricsConfig,
    MetricsReport,
    report_from_sums,
)
from trace_runtime.errors import LogReadError, UsageError

if TYPE_CHECKING:
    import duckdb

__all__ = [
    "DAY_MEANING",
    "INDEX_GROUP_BYS",
    "ColumnSession",
    "QueryResult",
    "connect",
    "find_decisions",
    "index_metrics",
    "index_robots",
    "run_query",
]

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


def _literal(text: str) -> str:
    """``text`` as a SQL string literal."""
    return "'" + text.replace("'", "''") + "'"


_SHELL_SAFE = _literal("[A-Za-z0-9_./+:@%=,-]+")
_QUOTE = _literal("'")
_QUOTE_IN_QUOTES = _literal("'\"'\"'")
_EXPLAIN = (
    "'trace-audit explain ' || "
    # The segment's absolute path, quoted for a POSIX shell unless it needs no quoting.
    f"CASE WHEN regexp_full_match(segment_path, {_SHELL_SAFE}) THEN segment_path "
    f"ELSE {_QUOTE} || replace(segment_path, {_QUOTE}, {_QUOTE_IN_QUOTES}) || {_QUOTE} END || "
    # Robot ids in the index are simple names (the folder's naming): no quoting needed.
    "' --cycle ' || CAST(cycle AS VARCHAR) || ' --robot ' || robot"
)
"""The exact decision: its segment file, its cycle number and its robot (a time would name
the decision in force then, and a float time not even that)."""

DAY_MEANING = (
    "the UTC date (YYYY-MM-DD) of the decision's time on a wall clock; on a sim or "
    "monotonic clock, whose times count from an arbitrary zero, the robot's run: "
    "run-<number of the run's first segment>"
)
"""What the index's ``day`` column (and ``metrics --index --by day``) means."""


@dataclass(frozen=True, slots=True)
class QueryResult:
    """Rows of a query, with their column names."""

    columns: tuple[str, ...]
    rows: list[tuple[Any, ...]]
    elapsed_s: float
    total: int | None = None
    """Rows the statement gave when more than ``rows`` (cut by a limit); None when whole."""

    def records(self) -> list[dict[str, Any]]:
        """Rows as JSON-ready dicts (dates as ISO text)."""
        return [{c: plain(v) for c, v in zip(self.columns, row, strict=True)} for row in self.rows]


def plain(value: Any) -> Any:
    """A DuckDB value as JSON-ready data: DECIMAL as a number, dates and times as ISO 8601
    text, INTERVAL as an ISO 8601 duration, UUID as text, BLOB as hex."""
    if isinstance(value, datetime.date | datetime.datetime | datetime.time):
        return value.isoformat()
    if isinstance(value, datetime.timedelta):
        return _duration(value)
    if isinstance(value, decimal.Decimal):
        exponent = value.as_tuple().exponent
        return int(value) if isinstance(exponent, int) and exponent >= 0 else float(value)
    if isinstance(value, uuid.UUID):
        return str(value)
    if isinstance(value, bytes | bytearray | memoryview):
        return bytes(value).hex()
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    return value


def _duration(value: datetime.timedelta) -> str:
    sign = "-" if value < datetime.timedelta(0) else ""
    value = abs(value)
    hours, rest = divmod(value.seconds, 3600)
    minutes, seconds = divmod(rest, 60)
    clock = ""
    if hours:
        clock += f"{hours}H"
    if minutes:
        clock += f"{minutes}M"
    if seconds or value.microseconds:
        clock += f"{seconds + value.microseconds / 1e6:g}S"
    text = (f"{value.days}D" if value.days else "") + (f"T{clock}" if clock else "")
    return f"{sign}P{text or 'T0S'}"


def connect(
    index: str | Path, *, confined: bool = True, limits: QueryLimits | None = None
) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB with the index's tables as views; ``LogReadError`` when
    ``index`` is not a fleet index of this version. ``confined`` (the CLI's only mode):
    the session reads the index's files and nothing else, within ``limits`` (memory and
    threads; the defaults when None); off, it is a full DuckDB (a script of the caller's
    own that also writes files, e.g. ``bench/``)."""
    import duckdb

    root = Path(index)
    manifest = load_manifest(root)
    if manifest is None:
        raise LogReadError(str(root), "not a fleet index (run trace-audit index first)")
    # No progress bar: DuckDB draws one on the terminal for long queries, into our output.
    con = duckdb.connect(":memory:")
    con.execute("SET enable_progress_bar = false")
    # Only the index's own files inside the folder (``folder.listed_files``): a name the
    # manifest lists outside it would otherwise widen what the session may read.
    listed = listed_files(root, manifest)
    for table in TABLES:
        # The files the manifest lists, not a glob: a stray or leftover file in the
        # directory is not the index's and must not be counted.
        files = [(root / rel).as_posix() for rel in listed if rel.startswith(f"{table}/")]
        if files:
            names = ", ".join(_literal(f) for f in files)
            source = (
                f"read_parquet([{names}], hive_partitioning = true, "
                "hive_types = {'robot': VARCHAR, 'day': VARCHAR})"
            )
        else:  # no rows yet (e.g. no gaps): an empty view of the right shape
            import pyarrow as pa

            empty = schema(table).empty_table()
            empty = empty.append_column("robot", pa.array([], pa.string()))
            empty = empty.append_column("day", pa.array([], pa.string()))
            con.register(f"_empty_{table}", empty)
            source = f"_empty_{table}"
        extra = f", {_EXPLAIN} AS explain" if table == "decisions" else ""
        try:
            con.execute(f"CREATE VIEW {table} AS SELECT *{extra} FROM {source}")
        except duckdb.Error as err:  # a listed file gone or damaged: the index is unreadable
            con.close()
            first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
            raise LogReadError(
                str(root), f"{first} (run trace-audit index again to rebuild it)"
            ) from err
    # The index's files and nothing else: a query reads no other file, writes none (COPY,
    # ATTACH), loads no extension and reaches no network, and cannot undo this. The views
    # keep working (DuckDB checks each file against allowed_paths).
    if not confined:
        if limits is not None:
            limits.apply(con)
        return con
    (limits or QueryLimits()).apply(con)
    every = [(root / rel).as_posix() for rel in listed]
    con.execute("SET allowed_paths = ?", [every])
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")
    return con


def run_query(
    index: str | Path,
    sql: str,
    params: Sequence[Any] = (),
    *,
    limit: int | None = None,
    limits: QueryLimits | None = None,
) -> QueryResult:
    """Run one SQL statement on the index; a bad statement is a ``UsageError`` (one line),
    a Parquet file of the index that cannot be read a ``LogReadError``. With ``limit``,
    the rows past it are counted (not kept) so the result can say it was cut.

    Within ``limits`` (the defaults when None): a statement that runs too long, needs too
    much memory or gives too large a result is a ``UsageError`` naming the bound."""
    bounds = limits or QueryLimits()
    started = time.perf_counter()
    con = connect(index, limits=bounds)
    try:
        result: QueryResult = _guarded(
            index,
            con,
            bounds,
            lambda con: _run(con, sql, params, limit=limit, bounds=bounds, started=started),
        )
    finally:
        con.close()
    return result


class ColumnSession:
    """Statements on one confined session of an index, each result as numpy columns by
    name (a NULL in a numeric column is NaN, in a text column None), for readers of many
    rows (``check --index``): no Python row is built, and the session (its views over the
    index's files, about 0.3 s to set up on 10 robot-days) is opened once. The bounds and
    errors of ``run_query``, per statement. Not for sharing between threads."""

    def __init__(self, index: str | Path, limits: QueryLimits | None = None) -> None:
        self.index = index
        self.limits = limits or QueryLimits()
        self._con: duckdb.DuckDBPyConnection | None = None

    def __call__(self, sql: str, params: Sequence[Any] = ()) -> dict[str, Any]:
        bounds = self.limits

        def fetch(con: duckdb.DuckDBPyConnection) -> dict[str, Any]:
            columns = con.execute(sql, list(params)).fetchnumpy()
            held = sum(_column_bytes(c) for c in columns.values())
            if held > bounds.result_bytes:
                raise UsageError(
                    f"SQL: the result holds more than {format_size(bounds.result_bytes)} "
                    "(select fewer rows or columns)"
                )
            return {name: _unmasked(c) for name, c in columns.items()}

        if self._con is None:
            self._con = connect(self.index, limits=bounds)
        columns: dict[str, Any] = _guarded(self.index, self._con, bounds, fetch)
        return columns

    def close(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None

    def __enter__(self) -> ColumnSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _column_bytes(column: Any) -> int:
    """What a fetched column holds: its array's bytes, a text or list value counted at
    64 bytes (a Python object and its pointer; the values are not walked)."""
    return int(column.size * 64 if column.dtype == object else column.nbytes)


def _unmasked(column: Any) -> Any:
    """DuckDB's masked array of a column with NULLs as a plain one: NaN in numbers (as
    floats), None in anything else."""
    import numpy as np

    if not np.ma.isMaskedArray(column):
        return column
    if column.dtype.kind in "iufb":
        return np.ma.filled(column.astype(np.float64), np.nan)
    return np.ma.filled(column.astype(object), None)


def _guarded(
    index: str | Path, con: duckdb.DuckDBPyConnection, bounds: QueryLimits, work: Any
) -> Any:
    """``work(con)`` on a confined session of ``index`` under its watchdog; DuckDB's
    errors as the one-line errors of ``run_query``."""
    import duckdb

    try:
        with watchdog(con, bounds):
            return work(con)
    except (duckdb.Error, MemoryError) as err:
        refused = over_limit(err, bounds)
        if refused is not None:
            raise refused from err
        if isinstance(err, MemoryError):
            raise
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        if isinstance(err, duckdb.IOException | duckdb.InvalidInputException) and (
            ".parquet" in first
        ):  # the index's own file is damaged or gone: unreadable input, not a usage error
            raise LogReadError(str(index), f"SQL: {first}") from err
        raise UsageError(f"SQL: {first}") from err


def _run(
    con: duckdb.DuckDBPyConnection,
    sql: str,
    params: Sequence[Any],
    *,
    limit: int | None,
    bounds: QueryLimits,
    started: float,
) -> QueryResult:
    """``run_query`` on an open session, under its watchdog."""
    statements = con.extract_statements(sql)
    if not statements:
        raise UsageError("no SQL statement given (only blanks, ';' or comments)")
    if len(statements) > 1:
        raise UsageError(f"give one SQL statement at a time ({len(statements)} given)")
    cursor = con.execute(sql, list(params))
    if cursor.description is None:
        return QueryResult((), [], time.perf_counter() - started)
    columns = tuple(d[0] for d in cursor.description)
    rows = _fetch(cursor, limit, bounds)
    total = None if limit is None or len(rows) < limit else len(rows) + _rest(cursor)
    return QueryResult(
        columns,
        rows,
        time.perf_counter() - started,
        total=total if total is not None and total > len(rows) else None,
    )


def _fetch(cursor: Any, limit: int | None, bounds: QueryLimits) -> list[tuple[Any, ...]]:
    """Up to ``limit`` rows (all when None), a batch at a time; ``UsageError`` once they
    hold more than ``bounds.result_bytes``."""
    rows: list[tuple[Any, ...]] = []
    held = 0
    while limit is None or len(rows) < limit:
        want = 2048 if limit is None else min(2048, limit - len(rows))
        batch = cursor.fetchmany(want)
        for row in batch:
            held += row_bytes(row)
        if held > bounds.result_bytes:
            raise UsageError(
                f"SQL: the result holds more than {format_size(bounds.result_bytes)} "
                "(add a LIMIT, or select fewer or shorter columns)"
            )
        rows.extend(batch)
        if len(batch) < want:
            break
    return rows


def _rest(cursor: Any) -> int:
    """Rows left in a result, counted in Arrow batches (bounded memory, no Python rows)."""
    import warnings

    with warnings.catch_warnings():
        # DuckDB warns that Arrow output of a DB-API result copies rows: it is counted only.
        warnings.filterwarnings("ignore", message="Arrow output on a DB-API result")
        return sum(batch.num_rows for batch in cursor.to_arrow_reader(65_536))


def find_decisions(
    index: str | Path,
    *,
    action: str | None = None,
    near: str | None = None,
    within_m: float | None = None,
    where: str | None = None,
    robots: Sequence[str] = (),
    limit: int = 1000,
    limits: QueryLimits | None = None,
) -> QueryResult:
    """Decisions by command, by a perceived entity's class and distance, and by any SQL
    condition on the decisions' columns; each row with ``robot``, ``t_ns`` and ``explain``.

    ``robots``: only these robots' decisions (none: every robot's); a robot the index
    does not hold is a ``UsageError`` naming those it does (``index_robots``)."""
    conditions: list[str] = []
    params: list[Any] = []
    if action is not None:
        conditions.append("upper(d.command) = upper(?)")
        params.append(action)
    if robots:
        robots = _held_robots(index, robots, limits)
        # One placeholder per robot: the ids themselves only ever travel as parameters.
        conditions.append(f"d.robot IN ({', '.join('?' for _ in robots)})")
        params.extend(robots)
    if where:
        conditions.append(f"({where})")
    select = (
        "d.robot, d.day, d.t_ns, d.cycle, d.command, d.previous_command, d.lead_factor, "
        "d.lead_value, d.lead_unit, d.et, d.dr, d.seal_verified, d.software_version"
    )
    if near is not None or within_m is not None:
        # From the decision's own ``nearest`` map (class -> nearest distance), built from
        # the same entity rows: one scan of one table, no join of two fleet-sized ones.
        if near is not None:
            distance = f"d.nearest[{_literal(near)}]"
            select += f", {_literal(near)} AS nearest_class"
        else:
            distance = "list_min(map_values(d.nearest))"
            select += (
                ", map_keys(d.nearest)[list_position(map_values(d.nearest), "
                f"{distance})] AS nearest_class"
            )
        select += f", {distance} AS nearest_m"
        conditions.append(f"{distance} IS NOT NULL")
        if within_m is not None:
            if not math.isfinite(within_m):
                raise UsageError(f"--within must be a finite distance, got {within_m}")
            conditions.append(f"{distance} < {float(within_m)!r}")
    sql = f"SELECT {select}, d.explain FROM decisions d"
    if conditions:
        sql += " WHERE " + " AND ".join(conditions)
    try:
        ordered = sql + f" ORDER BY d.t_ns, d.robot LIMIT {int(limit)}"
        found = run_query(index, ordered, params, limits=limits)
    except UsageError as err:
        if where:  # the error is about SQL the user did not write around the condition
            raise UsageError(f"--where {where!r}: {err}") from err
        raise
    if len(found.rows) < limit:
        return found
    # As many rows as the limit: count the matches so the output can say it was cut.
    count = run_query(index, f"SELECT count(*) FROM ({sql})", params, limits=limits).rows[0][0]
    return dataclasses.replace(found, total=int(count) if count > len(found.rows) else None)


def index_robots(index: str | Path, limits: QueryLimits | None = None) -> list[str]:
    """The robots the index holds (those with an indexed segment), sorted."""
    found = run_query(index, "SELECT DISTINCT robot FROM segments ORDER BY robot", limits=limits)
    return [str(row[0]) for row in found.rows]


def _held_robots(index: str | Path, robots: Sequence[str], limits: QueryLimits | None) -> list[str]:
    """``robots`` once each; ``UsageError`` naming the index's robots when one is not held."""
    wanted = list(dict.fromkeys(robots))
    held = index_robots(index, limits)
    missing = [repr(r) for r in wanted if r not in held]
    if missing:
        holds = ", ".join(held) if held else "no robot"
        raise UsageError(f"robot {', '.join(missing)} is not in this index; it holds {holds}")
    return wanted


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
    tcs = (
        f"CASE WHEN {gate} THEN 0.0 ELSE ({w.et!r} * et + {w.et_partial!r} * et_partial + "
        f"{w.dr!r} * dr::DOUBLE + {w.continuity!r} * continuity + "
        f"{w.integrity!r} * seal_verified::DOUBLE) / {total!r} END"
    )
    return f"""
        WITH d AS (SELECT *, {group} AS g, {tcs} AS tcs_w FROM decisions)
        SELECT g, count(*), sum(sealed::INT), sum(summarized::INT),
               fsum(et), fsum(et * et), fsum(et_partial), fsum(et_partial * et_partial),
               sum((factors_total > 0 AND factors_traceable = factors_total)::INT),
               sum(factors_total), sum(factors_traceable), sum((factors_total = 0)::INT),
               sum(dr::INT), sum(seal_verified::INT), fsum(tcs_w), fsum(tcs_w * tcs_w),
               sum(window_ns), sum(gap_ns), sum((gap_ns > 0)::INT), sum(missing_cycles),
               sum(dropped), sum(clock_anomaly::INT), list(DISTINCT segment),
               count(*) FILTER (WHERE NOT (factors_total > 0
                   AND factors_traceable = factors_total AND dr AND seal_verified))
        FROM d GROUP BY g ORDER BY g
    """


def _group_sums(row: Sequence[Any]) -> tuple[str, GroupSums, list[str], int]:
    """One row of ``_sums_sql``: (group, its sums, its segments, its failing decisions)."""
    (name, n, sealed, summarized, et, et2, etp, etp2, full, factors, traceable) = row[:11]
    (no_factors, dr, intact, tcs_sum, tcs2, window, gap, gaps, missing) = row[11:20]
    (dropped, anomalies, names, failing) = row[20:]
    sums = GroupSums(
        decisions=n,
        sealed=sealed,
        summarized=summarized,
        et_sum=et,
        et_sq=et2,
        etp_sum=etp,
        etp_sq=etp2,
        full=full,
        factors=factors,
        factors_traceable=traceable,
        no_factors=no_factors,
        dr_ok=dr,
        integrity_ok=intact,
        tcs_sum=tcs_sum,
        tcs_sq=tcs2,
        window_ns=int(window),
        gap_ns=int(gap),
        gaps=gaps,
        missing_cycles=int(missing),
        dropped=int(dropped),
        anomalies=anomalies,
    )
    return str(name), sums, names, failing
