"""SQL over the index is bounded: a statement that runs too long is stopped, one that asks
for too much memory or gives too large a result is refused, each in one line with exit 2,
and the session cannot lift its own bounds. Run from the outside: the CLI in a subprocess,
its peak memory read by a parent process of its own (``hostile.run_cli``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.trace_audit.conftest import write_log
from tests.trace_runtime import hostile
from trace_audit.fleet.find import find_decisions
from trace_audit.fleet.index import build_index
from trace_audit.fleet.limits import QueryLimits, parse_size
from trace_audit.fleet.query import run_query
from trace_runtime.errors import UsageError

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def index(tmp_path_factory: pytest.TempPathFactory) -> Path:
    base = tmp_path_factory.mktemp("limits")
    root = write_log(base / "logs", robot_id="r1")
    build_index([root], base / "idx")
    return base / "idx"


def _measured(*args: str | Path) -> tuple[int, int, str]:
    """(exit code, peak RSS in bytes, stderr) of one CLI run, measured by a fresh parent."""
    run = hostile.run_cli([str(a) for a in args], timeout_s=120)
    return run.code, int(run.rss_mb * 2**20), run.stderr


def _refused(stderr: str, *needles: str) -> None:
    assert stderr.count("\n") == 1 and "Traceback" not in stderr, stderr
    for needle in needles:
        assert needle in stderr, stderr


def test_a_statement_that_runs_too_long_is_stopped(index: Path) -> None:
    started = time.monotonic()
    code, _, err = _measured(
        "query", index, "SELECT count(*) FROM range(1e12::BIGINT)", "--timeout", "2"
    )
    assert code == 2
    _refused(err, "stopped after 2 s", "--timeout")
    assert time.monotonic() - started < 60  # the statement alone needs hours


@pytest.mark.parametrize(
    "sql",
    [
        "SELECT repeat('x', 2000000000)",  # 2 GB outside DuckDB's buffer manager
        "SELECT list(range(300000000))",
        "SELECT string_agg(i::VARCHAR, ',') FROM range(100000000) t(i)",
    ],
)
def test_a_statement_that_needs_too_much_memory_is_refused_within_the_cap(
    index: Path, sql: str
) -> None:
    code, peak, err = _measured("query", index, sql, "--memory-limit", "256MB", "--json")
    assert code == 2
    _refused(err, "--memory-limit 256 MB")
    assert peak < 10**9, peak  # each takes 2.9 to 15 GB unbounded


def test_a_result_larger_than_the_cap_is_refused(index: Path) -> None:
    code, _, err = _measured("query", index, "SELECT repeat('x', 1000) FROM range(1000000)")
    assert code == 2
    _refused(err, "more than 256 MB", "LIMIT")


@pytest.mark.parametrize("sql", ["SET memory_limit = '100GB'", "SET threads = 256"])
def test_a_statement_cannot_lift_its_own_bounds(index: Path, sql: str) -> None:
    code, _, err = _measured("query", index, sql)
    assert code == 2
    _refused(err, "SQL:")


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("--memory-limit", "lots"), "--memory-limit must be a size"),
        (("--memory-limit", "1kB"), "at least 16 MiB"),
        (("--timeout", "0"), "--timeout must be more than 0"),
    ],
)
def test_bad_bounds_are_usage_errors(index: Path, args: tuple[str, ...], needle: str) -> None:
    for command in (("query", index, "SELECT 1"), ("find", index), ("metrics", "--index", index)):
        code, _, err = _measured(*command, *args)
        assert code == 2, command
        _refused(err, needle)


def test_bounds_without_an_index_are_a_usage_error(index: Path) -> None:
    code, _, err = _measured("metrics", index.parent / "logs", "--timeout", "5")
    assert code == 2
    _refused(err, "--index only")


def test_metrics_from_the_index_runs_within_raised_bounds(index: Path) -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "trace_audit.cli",
            "metrics",
            "--index",
            str(index),
            "--json",
            "--memory-limit",
            "2GiB",
            "--timeout",
            "120",
        ],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["overall"]["decisions"] == 100


def test_the_library_applies_the_same_bounds(index: Path) -> None:
    """No process cap for a library caller (the process is theirs); DuckDB's own limits,
    the watchdog and the result cap hold."""
    with pytest.raises(UsageError, match="stopped after 1 s"):
        run_query(
            index, "SELECT count(*) FROM range(1e12::BIGINT)", limits=QueryLimits(timeout_s=1)
        )
    with pytest.raises(UsageError, match="more than 1 kB"):
        find_decisions(index, limits=QueryLimits(result_bytes=1000))
    assert run_query(
        index, "SELECT current_setting('threads')", limits=QueryLimits(threads=1)
    ).rows == [(1,)]


@pytest.mark.parametrize(
    ("text", "size"),
    [("1GB", 10**9), ("512MiB", 512 * 2**20), ("2e9", 2 * 10**9), (" 16 mib ", 16 * 2**20)],
)
def test_sizes_read_as_people_write_them(text: str, size: int) -> None:
    assert parse_size(text) == size


def test_the_app_inside_someone_elses_process_leaves_its_limits_alone(index: Path) -> None:
    """Only the CLI's own process is capped: a caller running the app in theirs (this test
    runner) keeps its limits, which its later children (a browser) would inherit."""
    import resource

    from typer.testing import CliRunner

    from trace_audit.cli import app

    before = resource.getrlimit(resource.RLIMIT_DATA)
    done = CliRunner().invoke(app, ["query", str(index), "SELECT 1", "--memory-limit", "64MB"])
    assert done.exit_code == 0, done.output
    assert resource.getrlimit(resource.RLIMIT_DATA) == before
