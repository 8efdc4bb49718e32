"""An index whose Parquet files someone damaged: a column missing or retyped (rewritten with
pyarrow, the way another tool or a careless edit would), in the file that sets the table's
shape or a later one. Every command that reads the index says so in one line, exit 3
(damaged input), never exit 2 as if the user's SQL were wrong."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import write_log

RULES = '[[rule]]\nname = "keeps_away"\nstl = "always(nearest.person >= 0.5)"\n'


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("damaged")
    root = write_log(where / "logs", robot_id="r1", max_segment_s=3.0)
    done = cli("index", root, "--out", where / "idx")
    assert done.returncode == 0, done.stderr
    return where / "idx"


def _damaged(index: Path, tmp_path: Path, how: str, column: str, which: int) -> Path:
    """A copy of ``index`` whose ``which``-th decisions file lacks ``column`` or holds it
    as another type."""
    copy = tmp_path / "idx"
    shutil.copytree(index, copy)
    path = sorted((copy / "decisions").rglob("*.parquet"))[which]
    table = pq.read_table(path)
    at = table.schema.get_field_index(column)
    if how == "missing":
        table = table.remove_column(at)
    else:  # a text column where numbers were: what a CSV round trip makes of one
        table = table.set_column(at, column, pa.array(["n/a"] * table.num_rows))
    pq.write_table(table, path)
    return copy


def _commands(index: Path, tmp_path: Path, column: str) -> list[tuple[str | Path, ...]]:
    rules = tmp_path / "rules.toml"
    rules.write_text(RULES, encoding="utf-8")
    return [
        ("query", index, f"SELECT {column}, count(*) FROM decisions GROUP BY ALL"),
        ("query", index, "SELECT avg(tcs), max(t_ns), min(cycle) FROM decisions"),
        ("find", index, "--action", "STOP"),
        ("metrics", "--index", index),
        ("check", "--index", index, "--rules", rules),
    ]


@pytest.mark.parametrize("column", ["cycle", "t_ns", "tcs"])
def test_a_column_missing_from_the_first_file_is_exit_3_on_every_reader(
    index: Path, tmp_path: Path, column: str
) -> None:
    """The first file of a table sets the columns of its view: every reader is refused."""
    damaged = _damaged(index, tmp_path, "missing", column, 0)
    for args in _commands(damaged, tmp_path, column):
        one_line(cli(*args), 3, "decisions", column)


@pytest.mark.parametrize("which", [0, 1], ids=["first-file", "later-file"])
@pytest.mark.parametrize("how", ["missing", "retyped"])
@pytest.mark.parametrize("column", ["cycle", "t_ns", "tcs"])
def test_a_damaged_column_is_exit_3_where_it_is_read(
    index: Path, tmp_path: Path, how: str, column: str, which: int
) -> None:
    """A file is checked as DuckDB reads it: a statement that reads the damaged column
    is refused, naming it; one that does not (a count) may answer, and whatever answers
    or fails does so as exit 0 or 3, never as the user's SQL (2)."""
    damaged = _damaged(index, tmp_path, how, column, which)
    commands = _commands(damaged, tmp_path, column)
    one_line(cli(*commands[0]), 3, "decisions", column)
    for args in commands[1:]:
        done = cli(*args)
        if done.returncode != 0:
            one_line(done, 3, "decisions")


def test_a_typo_in_the_users_sql_on_a_whole_index_stays_exit_2(index: Path) -> None:
    one_line(cli("query", index, "SELECT cylce FROM decisions"), 2, "cylce")
