"""SQL over the fleet index on DuckDB (embedded, no server): a confined session of the
index's own files (``connect``), one bounded statement (``run_query``), and a session whose
results are numpy columns (``ColumnSession``). The named questions built on it live beside
it: ``fleet.find`` (decisions) and ``fleet.metrics`` (metrics without re-reading the logs).

The tables are views over the Parquet files (Hive partitions ``robot`` and ``day`` come back
as columns; ``day`` is text: the UTC date on a wall clock, ``run-<segment>`` on a sim or
monotonic clock). ``decisions`` gains ``explain``: the exact ``trace-audit explain`` command
that reconstructs the row's decision from its segment, by cycle and robot.
"""

from __future__ import annotations

import datetime
import decimal
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from trace_audit.fleet.folder import listed_files, load_manifest
from trace_audit.fleet.limits import QueryLimits, format_size, over_limit, row_bytes, watchdog
from trace_audit.fleet.tables import PARTITION_COLUMNS, TABLES, sql_columns
from trace_runtime.errors import LogReadError, UsageError

if TYPE_CHECKING:
    import duckdb
    import numpy as np
    from numpy.typing import NDArray

T = TypeVar("T")

__all__ = [
    "ColumnSession",
    "QueryResult",
    "connect",
    "plain",
    "run_query",
    "sql_literal",
]


def sql_literal(text: str) -> str:
    """``text`` as a SQL string literal."""
    return "'" + text.replace("'", "''") + "'"


_SHELL_SAFE = sql_literal("[A-Za-z0-9_./+:@%=,-]+")
_QUOTE = sql_literal("'")
_QUOTE_IN_QUOTES = sql_literal("'\"'\"'")
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


@dataclass(frozen=True, slots=True)
class QueryResult:
    """Rows of a query, with their column names."""

    columns: tuple[str, ...]
    rows: list[tuple[object, ...]]
    """Each row's values as DuckDB gives them (any SQL type: ``plain`` makes them JSON)."""
    elapsed_s: float
    total: int | None = None
    """Rows the statement gave when more than ``rows`` (cut by a limit); None when whole."""

    def records(self) -> list[dict[str, object]]:
        """Rows as JSON-ready dicts (dates as ISO text)."""
        return [{c: plain(v) for c, v in zip(self.columns, row, strict=True)} for row in self.rows]


def plain(value: object) -> object:
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
    try:
        for table in TABLES:
            # The files the manifest lists, not a glob: a stray or leftover file in the
            # directory is not the index's and must not be counted.
            _create_view(con, table, [(root / r).as_posix() for r in listed if _of(r, table)])
    except duckdb.Error as err:  # a listed file gone or damaged: the index is unreadable
        con.close()
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise LogReadError(
            str(root), f"{first} (run trace-audit index again to rebuild it)"
        ) from err
    except LogReadError:
        con.close()
        raise
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


def _of(rel: str, table: str) -> bool:
    return rel.startswith(f"{table}/")


def _create_view(con: duckdb.DuckDBPyConnection, table: str, files: list[str]) -> None:
    """View ``table`` over ``files``: the table's columns, each cast to its type, the
    partition columns and, for decisions, the explain column; of no file, an empty view of
    the same shape. A file's column of another type is cast, so the view is always of the
    table's types (a cast of a column already of its type is no work for DuckDB); a value
    that will not cast fails as it is read (``_guarded``). A first file that lacks a
    column is a ``LogReadError`` naming it; a later one DuckDB reports as it reads it."""
    import duckdb

    shape = sql_columns(table)
    extra = f", {_EXPLAIN} AS explain" if table == "decisions" else ""
    if not files:  # no rows yet (e.g. no gaps): typed NULLs, no row
        nulls = ", ".join(f'CAST(NULL AS {kind}) AS "{name}"' for name, kind in shape)
        partitions = ", ".join(f"CAST(NULL AS VARCHAR) AS {c}" for c in PARTITION_COLUMNS)
        con.execute(f"CREATE VIEW {table} AS SELECT {nulls}, {partitions}{extra} LIMIT 0")
        return
    names = ", ".join(sql_literal(f) for f in files)
    source = (
        f"read_parquet([{names}], hive_partitioning = true, "
        "hive_types = {'robot': VARCHAR, 'day': VARCHAR})"
    )
    typed = ", ".join(f'CAST("{name}" AS {kind}) AS "{name}"' for name, kind in shape)
    try:
        con.execute(
            f"CREATE VIEW {table} AS SELECT {typed}, {', '.join(PARTITION_COLUMNS)}{extra} "
            f"FROM {source}"
        )
    except duckdb.Error as err:  # a column missing, or of a type that cannot be cast
        got = _described(con, f"SELECT * FROM {source}")
        damage = _mismatch(table, files[0], dict(shape), got)
        if damage is not None:
            raise damage from err
        raise


def run_query(
    index: str | Path,
    sql: str,
    params: Sequence[object] = (),
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

    def __call__(self, sql: str, params: Sequence[object] = ()) -> dict[str, NDArray[np.generic]]:
        bounds = self.limits

        def fetch(con: duckdb.DuckDBPyConnection) -> dict[str, NDArray[np.generic]]:
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
        return _guarded(self.index, self._con, bounds, fetch)

    def close(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None

    def __enter__(self) -> ColumnSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _column_bytes(column: NDArray[np.generic]) -> int:
    """What a fetched column holds: its array's bytes, a text or list value counted at
    64 bytes (a Python object and its pointer; the values are not walked)."""
    return int(column.size * 64 if column.dtype == object else column.nbytes)


def _unmasked(column: NDArray[np.generic]) -> NDArray[np.generic]:
    """DuckDB's masked array of a column with NULLs as a plain one: NaN in numbers (as
    floats), None in anything else."""
    import numpy as np

    if not np.ma.isMaskedArray(column):
        return column
    if column.dtype.kind in "iufb":
        return np.ma.filled(column.astype(np.float64), np.nan)
    return np.ma.filled(column.astype(object), None)


def _guarded(
    index: str | Path,
    con: duckdb.DuckDBPyConnection,
    bounds: QueryLimits,
    work: Callable[[duckdb.DuckDBPyConnection], T],
) -> T:
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
        if _names_a_file(first, index) or (
            isinstance(err, duckdb.IOException | duckdb.InvalidInputException)
            and ".parquet" in first
        ):  # the index's own file is damaged or gone: unreadable input, not a usage error
            raise LogReadError(str(index), f"SQL: {first}") from err
        if isinstance(err, duckdb.ConversionException):
            # A value that will not cast, and DuckDB did not say whose: the statement's own
            # (a CAST of the user's) or a file's whose column is of another type.
            damage = _damaged_file(con, index)
            if damage is not None:
                raise damage from err
        raise UsageError(f"SQL: {first}") from err


def _damaged_file(con: duckdb.DuckDBPyConnection, index: str | Path) -> LogReadError | None:
    """The first file of the index whose columns are not its table's, or None. Each
    file's footer is read: for an error's explanation only, never on the way of a
    statement that succeeds."""
    root = Path(index)
    manifest = load_manifest(root)
    listed = listed_files(root, manifest) if manifest is not None else []
    for table in TABLES:
        want = dict(sql_columns(table))
        for path in [(root / rel).as_posix() for rel in listed if _of(rel, table)]:
            got = _described(con, f"SELECT * FROM read_parquet({sql_literal(path)})")
            damage = _mismatch(table, path, want, got)
            if damage is not None:
                return damage
    return None


def _described(con: duckdb.DuckDBPyConnection, select: str) -> dict[str, str]:
    """The columns of a SELECT (or a view) and their DuckDB types (bound, not run)."""
    return {row[0]: row[1] for row in con.execute(f"DESCRIBE {select}").fetchall()}


def _mismatch(
    table: str, path: str, want: dict[str, str], got: dict[str, str]
) -> LogReadError | None:
    """The error for file ``path`` of ``table`` when a column ``want`` names is missing
    from ``got`` or of another type there; None when every one is as wanted."""
    for name, kind in want.items():
        # DuckDB quotes a struct field's name only where it is a keyword: compared without
        if got.get(name, "").replace('"', "") != kind.replace('"', ""):
            held = "has no such column" if name not in got else f"holds it as {got[name]}"
            return LogReadError(
                path,
                f"damaged index file: the {table} table's column {name!r} ({kind}) {held} "
                "(run trace-audit index again to rebuild it)",
            )
    return None


def _names_a_file(message: str, index: str | Path) -> bool:
    """Whether DuckDB's ``message`` is about a file inside ``index`` (a value of a file that
    cannot be cast to its column's type): the session reads no other file, so the damage
    is the index's, whatever the statement."""
    return f'file "{Path(index).as_posix()}/' in message


def _run(
    con: duckdb.DuckDBPyConnection,
    sql: str,
    params: Sequence[object],
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


def _fetch(
    cursor: duckdb.DuckDBPyConnection, limit: int | None, bounds: QueryLimits
) -> list[tuple[object, ...]]:
    """Up to ``limit`` rows (all when None), a batch at a time; ``UsageError`` once they
    hold more than ``bounds.result_bytes``."""
    rows: list[tuple[object, ...]] = []
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


def _rest(cursor: duckdb.DuckDBPyConnection) -> int:
    """Rows left in a result, counted in Arrow batches (bounded memory, no Python rows)."""
    import warnings

    with warnings.catch_warnings():
        # DuckDB warns that Arrow output of a DB-API result copies rows: it is counted only.
        warnings.filterwarnings("ignore", message="Arrow output on a DB-API result")
        reader = cursor.to_arrow_reader(65_536)
        # None only for a statement without a result; ``_run`` counts only after rows came.
        assert reader is not None
        return sum(batch.num_rows for batch in reader)
