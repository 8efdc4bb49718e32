"""``trace-audit index``, ``query`` and ``find``: the fleet index and SQL over it."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_USAGE, app, fail, guarded, help_text
from trace_audit.cli.doc import Column, Doc
from trace_audit.cli.find_doc import found_doc
from trace_audit.cli.options import (
    CsvOption,
    IndexArgument,
    JsonOption,
    MemoryLimitOption,
    PlainOption,
    RobotsOption,
    SchedulerOption,
    SqlTimeoutOption,
    action_option,
    cluster,
    jobs_option,
    limit_option,
    sql_limits,
)
from trace_audit.cli.output import emit, print_json, progress_bar
from trace_audit.fleet.limits import QueryLimits, format_size

if TYPE_CHECKING:  # the library is imported inside each command: start-up stays light
    from trace_audit.fleet.index import IndexReport
    from trace_audit.fleet.query import QueryResult

_INDEX_HELP = help_text("""
Build or update the fleet index: Parquet tables of every decision (decisions, entities,
actuator channels, checks, gaps, segments), partitioned by robot and day, scored by the same
code as metrics. The day is the UTC date on a wall clock; on a sim or monotonic clock it is
the robot's run, run-<first segment>. Only new or changed segments are read (keyed by their
SHA-256). Schema: docs/fleet.md.

[bold]Examples[/bold]:

  trace-audit index logs/ --out idx/

  trace-audit index logs/ --out idx/ --scheduler tcp://10.0.0.5:8786

  trace-audit index sim1/ sim2/ --out idx/

Two different logs at one chain position (two roots whose robot has the same id) are
refused, exit 2; of two copies of one segment (a truncated one beside the intact file)
the intact one is indexed and the other named in a note.
""")


@app.command("index", help=_INDEX_HELP)
def index_command(
    logs: Annotated[
        list[Path],
        typer.Argument(help="Log files, directories or log roots.", show_default=False),
    ],
    *,
    out: Annotated[
        Path, typer.Option("--out", "-o", help="The index directory.", show_default=False)
    ],
    jobs: Annotated[int, jobs_option("Local processes to spread segments over.")] = 1,
    scheduler: SchedulerOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    def run() -> IndexReport:
        from trace_audit.fleet.index import build_index

        with cluster(scheduler) as executor:
            if json_out or plain or not sys.stderr.isatty():
                return build_index(logs, out, workers=jobs, executor=executor)
            with progress_bar("indexing cycles") as bar:
                task = bar.task_ids[0]

                def progress(done: int, expected: int | None) -> None:
                    bar.update(task, completed=done, total=expected)

                return build_index(logs, out, workers=jobs, executor=executor, progress=progress)

    report = guarded(run)
    emit(report, _index_doc, json_out=json_out, plain=plain)


def _index_doc(r: IndexReport) -> Doc:
    doc = Doc()
    doc.title(f"Fleet index in {r.index} (version {r.version})")  # "index" is often its name
    doc.fields(
        [
            (
                "segments",
                f"{r.segments} in the index; of this run's inputs {len(r.indexed)} indexed now, "
                f"{r.unchanged} unchanged"
                + (f", {len(r.notes)} left out (notes below)" if r.notes else ""),
            ),
            ("decisions", f"{r.decisions_total} ({r.decisions_written} written now)"),
            ("files", f"{r.files}, {r.bytes / 1e6:.2f} MB"),
            ("speed", f"{r.cycles_per_s:,.0f} cycles/s over {r.elapsed_s:.2f} s"),
        ]
    )
    for problem in r.unreadable:
        doc.line(f"unreadable, not indexed: {problem}")
    for note in r.notes:
        doc.line(f"note: {note}")
    return doc


_BOUNDS = QueryLimits()
_QUERY_HELP = help_text(f"""
Run one SQL statement (DuckDB) on a fleet index. Tables: decisions (with an explain
column: the command that reconstructs the decision), entities, channels, checks, gaps,
segments; robot and day on each (day: the UTC date, or run-<segment> on a sim clock).
A bad statement, none or several is one line on stderr, exit 2; a damaged index file,
exit 3. The statement reads the index's files and nothing else: other files,
COPY, ATTACH, extensions and the network are refused (export with --csv or --json, or
point DuckDB itself at the Parquet files). SQL that starts with a comment (--) goes
after a lone --.

A runaway statement is stopped, one line on stderr, exit 2: by default after
{_BOUNDS.timeout_s:g} s (--timeout), once DuckDB needs more than
{format_size(_BOUNDS.memory_bytes)} of memory (--memory-limit; the process is capped at
twice it), or once its result holds more than {format_size(_BOUNDS.result_bytes)}.

[bold]Examples[/bold]:

  trace-audit query idx/ "SELECT robot, avg(et) FROM decisions GROUP BY ALL"

  trace-audit query idx/ --csv "SELECT * FROM gaps ORDER BY gap_ns DESC"

  trace-audit query idx/ --json -- "$(cat stops-per-robot.sql)"
""")


@app.command("query", help=_QUERY_HELP)
def query_command(
    index: IndexArgument,
    sql: Annotated[str, typer.Argument(help="One SQL statement.", show_default=False)],
    *,
    csv_out: CsvOption = False,
    limit: Annotated[int | None, limit_option("Print at most this many rows.", least=0)] = None,
    memory_limit: MemoryLimitOption = None,
    timeout: SqlTimeoutOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.fleet.query import run_query

    _one_format(json_out=json_out, csv_out=csv_out)
    result = guarded(
        lambda: run_query(index, sql, limit=limit, limits=sql_limits(memory_limit, timeout))
    )
    _print_rows(result, json_out=json_out, csv_out=csv_out, plain=plain)


_FIND_HELP = help_text("""
Find decisions by command, by what the robot saw near it, and by any SQL condition on
the decisions table; each row ends with the explain command that reconstructs it
(trace-audit explain SEGMENT --cycle N --robot R).

[bold]Examples[/bold]:

  trace-audit find idx/ --action STOP --near person --within 1.0

  trace-audit find idx/ --action STOP --where "software_version='2.4'" --json

  trace-audit find idx/ --action STOP --robot amr-7 --robot amr-9
""")


@app.command("find", help=_FIND_HELP)
def find_command(
    index: IndexArgument,
    *,
    action: Annotated[str | None, action_option("The command, e.g. STOP.")] = None,
    near: Annotated[
        str | None,
        typer.Option(
            "--near", help="A perceived entity's class as logged, e.g. person.", show_default=False
        ),
    ] = None,
    within: Annotated[
        float | None,
        typer.Option(
            "--within",
            help="... closer than this many metres (without --near: an entity of any class).",
            show_default=False,
        ),
    ] = None,
    where: Annotated[
        str | None,
        typer.Option("--where", help="SQL condition on decisions (alias d).", show_default=False),
    ] = None,
    robot: RobotsOption = None,
    limit: Annotated[int, limit_option("At most this many rows, oldest first.", least=1)] = 1000,
    memory_limit: MemoryLimitOption = None,
    timeout: SqlTimeoutOption = None,
    csv_out: CsvOption = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.fleet.find import find_decisions

    _one_format(json_out=json_out, csv_out=csv_out)
    result = guarded(
        lambda: find_decisions(
            index,
            action=action,
            near=near,
            within_m=within,
            where=where,
            robots=robot or (),
            limit=limit,
            limits=sql_limits(memory_limit, timeout),
        )
    )
    _print_rows(result, json_out=json_out, csv_out=csv_out, plain=plain, doc=found_doc)


def _one_format(*, json_out: bool, csv_out: bool) -> None:
    if json_out and csv_out:
        fail("give --json or --csv, not both", EXIT_USAGE)


def _print_rows(
    result: QueryResult,
    *,
    json_out: bool,
    csv_out: bool,
    plain: bool,
    doc: Callable[[QueryResult], Doc] | None = None,
) -> None:
    if (json_out or csv_out) and result.total is not None:
        # The rows go to stdout; that they were cut, to stderr.
        sys.stderr.write(f"trace-audit: note: {_count(result)}\n")
    if json_out:
        print_json(result.records())
        return
    if csv_out:
        import csv

        from trace_audit.fleet.query import plain as plain_value

        writer = csv.writer(sys.stdout)
        writer.writerow(result.columns)
        for row in result.rows:
            writer.writerow([_csv_cell(plain_value(v)) for v in row])
        return
    emit(result, doc or _rows_doc, json_out=False, plain=plain)


def _count(result: QueryResult) -> str:
    if result.total is None:
        return f"{len(result.rows)} rows"
    return f"{len(result.rows)} of {result.total} rows (--limit {len(result.rows)})"


def _csv_cell(value: object) -> object:
    """Nested values (lists, structs, maps) as JSON text a CSV reader can parse; any other
    value (``object``: a DuckDB value made plain) as the CSV writer writes it."""
    import json

    return json.dumps(value, ensure_ascii=False) if isinstance(value, list | dict) else value


_UNKNOWN_WHEN_NULL = frozenset({"et", "et_partial", "tcs"})
"""Index columns whose null means unknown (evidence in a recording not read), shown ``?``."""


def _rows_doc(result: QueryResult) -> Doc:
    doc = Doc()
    unknown = [c in _UNKNOWN_WHEN_NULL for c in result.columns]
    doc.table(
        [Column(c) for c in result.columns],
        (
            ["?" if v is None and q else _cell(v) for v, q in zip(r, unknown, strict=True)]
            for r in result.rows
        ),
    )
    doc.line(f"{_count(result)} in {result.elapsed_s * 1000:.0f} ms")
    return doc


def _cell(value: object) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list | dict):
        import json

        from trace_audit.fleet.query import plain as plain_value

        return json.dumps(plain_value(value), ensure_ascii=False)
    return str(value)


__all__ = ["find_command", "index_command", "query_command"]
