"""``query`` and ``find`` from the outside (the CLI): odd SQL is one line and an exit code,
every DuckDB value type prints as JSON and CSV, and cut results say they were cut."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

from tests.trace_audit.conftest import write_log
from trace_audit.cli import app
from trace_audit.fleet.index import build_index


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("fleetq")
    write_log(root / "logs", robot_id="r1", max_segment_s=3.0)
    build_index([root / "logs"], root / "idx")
    return root / "idx"


def _run(*args: str | Path) -> Result:
    return CliRunner(env={"COLUMNS": "120"}).invoke(app, [str(a) for a in args])


def _one_line(result: Result, code: int, *needles: str) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert result.exit_code == code, (result.stdout, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("trace-audit: "), result.stderr
    for needle in needles:
        assert needle in lines[0]


@pytest.mark.parametrize("sql", ["", "   ", ";", "-- only a comment\n"])
def test_no_statement_is_a_usage_error(index: Path, sql: str) -> None:
    _one_line(_run("query", index, "--", sql), 2, "no SQL statement")


def test_several_statements_are_refused(index: Path) -> None:
    _one_line(_run("query", index, "SELECT 1; SELECT 2"), 2, "one SQL statement")


def test_sql_that_starts_with_a_comment_runs_after_a_double_dash(index: Path) -> None:
    done = _run("query", index, "--json", "--", "-- the count\nSELECT count(*) AS n FROM decisions")
    assert done.exit_code == 0, done.stderr
    assert json.loads(done.stdout) == [{"n": 100}]


def test_every_duckdb_type_prints_as_json_and_csv(index: Path) -> None:
    sql = (
        "SELECT 100.0 * 1 AS dec, INTERVAL 1 DAY AS iv, "
        "'3516179c-6e61-4097-bb65-dfc0ccf08761'::UUID AS id, TIME '12:00' AS tm, "
        "'ab'::BLOB AS raw, 1::HUGEINT AS big, {'a': [1, 2]} AS nested, MAP {'person': 0.5} AS m"
    )
    done = _run("query", index, sql, "--json")
    assert done.exit_code == 0, (done.stderr, done.exception)
    [row] = json.loads(done.stdout)
    assert row["dec"] == 100.0 and row["big"] == 1
    assert row["id"] == "3516179c-6e61-4097-bb65-dfc0ccf08761"
    assert row["tm"] == "12:00:00" and row["iv"] == "P1D" and row["raw"] == "6162"
    assert row["nested"] == {"a": [1, 2]} and row["m"] == {"person": 0.5}
    text = _run("query", index, sql, "--csv")
    assert text.exit_code == 0, text.stderr
    header, values = list(csv.reader(io.StringIO(text.stdout)))
    got = dict(zip(header, values, strict=True))
    assert json.loads(got["nested"]) == {"a": [1, 2]} and json.loads(got["m"]) == {"person": 0.5}


def test_a_damaged_parquet_file_is_unreadable_input(index: Path, tmp_path: Path) -> None:
    import shutil

    copy = tmp_path / "idx"
    shutil.copytree(index, copy)
    victim = sorted((copy / "decisions").rglob("*.parquet"))[0]
    victim.write_bytes(b"PAR1")
    _one_line(_run("query", copy, "SELECT count(*) FROM decisions"), 3, victim.name)


def test_a_cut_result_says_so(index: Path) -> None:
    done = _run("find", index, "--limit", "5", "--plain")
    assert done.exit_code == 0, done.stderr
    assert "5 of 100 decisions (--limit 5)" in done.stdout
    rows = _run("find", index, "--limit", "5", "--json")
    assert len(json.loads(rows.stdout)) == 5
    assert "5 of 100 rows" in rows.stderr
    whole = _run("query", index, "SELECT cycle FROM decisions", "--limit", "3", "--plain")
    assert "3 of 100 rows (--limit 3)" in whole.stdout
    uncut = _run("find", index, "--limit", "500", "--plain")
    assert "100 decisions" in uncut.stdout and " of " not in uncut.stdout.splitlines()[-1]


@pytest.mark.parametrize(
    "sql",
    [
        "COPY (SELECT 42 AS a) TO '{out}'",
        "SELECT * FROM read_csv('{secret}')",
        "ATTACH '{out}.db'",
        "INSTALL httpfs",
        "SET enable_external_access = true",
    ],
)
def test_query_reads_the_index_and_nothing_else(index: Path, tmp_path: Path, sql: str) -> None:
    """The views read the index's listed files; any other file or the network is refused
    (one line, exit 2), and nothing is written."""
    secret = tmp_path / "secret.csv"
    secret.write_text("a,b\n1,2\n", encoding="utf-8")
    out = tmp_path / "copied.csv"
    done = _run("query", index, sql.format(out=out, secret=secret))
    _one_line(done, 2)
    assert not out.exists() and not Path(f"{out}.db").exists()
    assert "1,2" not in done.stdout
    still = _run(
        "query",
        index,
        "SELECT count(*) AS n FROM decisions JOIN segments USING (segment)",
        "--json",
    )
    assert json.loads(still.stdout) == [{"n": 100}]


def test_help_examples_are_each_their_own_line() -> None:
    for command in ("index", "query", "find"):
        text = _run(command, "--help").stdout
        examples = [line.strip() for line in text.splitlines() if "trace-audit " + command in line]
        assert len(examples) >= 2, text
        assert all(line.count("trace-audit ") == 1 for line in examples), examples


def test_json_and_csv_together_is_a_usage_error(index: Path) -> None:
    _one_line(_run("query", index, "SELECT 1", "--json", "--csv"), 2, "--json or --csv")
    _one_line(_run("find", index, "--json", "--csv"), 2, "--json or --csv")


def test_a_bad_where_names_the_condition(index: Path) -> None:
    _one_line(_run("find", index, "--where", "garbage (("), 2, "--where 'garbage (('")
