"""The fleet index: rows equal what info and metrics read from the logs, updates are
incremental, and SQL errors are one line (exit 2)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from tests.trace_audit.conftest import T0_NS, write_log
from trace_audit.fleet.find import find_decisions
from trace_audit.fleet.index import MANIFEST, build_index
from trace_audit.fleet.metrics import index_metrics
from trace_audit.fleet.query import run_query
from trace_audit.fleet.tables import TABLES, schema
from trace_audit.info import log_info
from trace_audit.metrics import MetricsConfig, compute_metrics
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.tiers.compaction import compact

REPO = Path(__file__).resolve().parents[3]


def _fleet(root: Path) -> Path:
    """Two robots, several segments each; r2 drops three cycles (a gap)."""
    write_log(root, robot_id="r1", max_segment_s=3.0)
    write_log(
        root,
        robot_id="r2",
        max_segment_s=4.0,
        t0_ns=T0_NS + 500_000_000,
        skip=lambda i: i in (30, 31, 32),
    )
    return root


@pytest.fixture()
def fleet(tmp_path: Path) -> Path:
    return _fleet(tmp_path / "logs")


def _per_robot(index: Path) -> dict[str, int]:
    rows = run_query(index, "SELECT robot, count(*) FROM decisions GROUP BY robot").rows
    return {robot: n for robot, n in rows}


def test_rows_per_robot_equal_info_across_tiers(fleet: Path, tmp_path: Path) -> None:
    """With r1 compacted to cold and r2 hot, each robot's decision rows are info's cycles."""
    compact(fleet, "cold", older_than_ns=0, robot="r1")
    assert list((fleet / "cold").glob("r1_*.mcap"))
    report = build_index([fleet], tmp_path / "idx")
    info = log_info(fleet)
    expected = Counter[str]()
    for row in info.segments:
        expected[row.robot] += row.cycles
    assert _per_robot(tmp_path / "idx") == dict(expected)
    assert report.decisions_total == info.cycles
    tiers = dict(
        run_query(tmp_path / "idx", "SELECT robot, any_value(tier) FROM segments GROUP BY 1").rows
    )
    assert tiers == {"r1": "cold", "r2": "hot"}
    gaps = run_query(tmp_path / "idx", "SELECT robot, after_cycle, before_cycle FROM gaps").rows
    assert [(g.robot, g.after_cycle, g.before_cycle) for g in info.gaps] == gaps


def test_each_decision_row_has_the_et_and_dr_metrics_gives_it(fleet: Path, tmp_path: Path) -> None:
    """The decisions metrics lists as failing are exactly the rows that are not fully
    traceable, reconstructable and intact, with the same ET and ET_partial."""
    build_index([fleet], tmp_path / "idx")
    scan = compute_metrics([fleet], MetricsConfig(max_listed=10_000))
    listed = {(f.segment, f.cycle): (f.et, f.et_partial) for f in scan.failures}
    assert scan.failures_total == len(listed) > 0
    rows = run_query(
        tmp_path / "idx",
        "SELECT segment, cycle, et, et_partial, dr, seal_verified, dr_problems, "
        "factors_total = factors_traceable AND factors_total > 0 FROM decisions",
    ).rows
    failing = {
        (s, c): (et, etp) for s, c, et, etp, dr, ok, _p, full in rows if not (dr and ok and full)
    }
    assert failing == listed
    for f in scan.failures:
        row = next(r for r in rows if (r[0], r[1]) == (f.segment, f.cycle))
        assert [f"DR: {p}" for p in row[6]] == [p for p in f.problems if p.startswith("DR: ")]


@pytest.mark.parametrize("by", [None, "robot", "scenario", "segment", "hour"])
def test_metrics_from_the_index_equal_metrics_from_the_logs(
    fleet: Path, tmp_path: Path, by: str | None
) -> None:
    build_index([fleet], tmp_path / "idx")
    logs = compute_metrics([fleet], MetricsConfig(by=by))  # type: ignore[arg-type]
    index = index_metrics(tmp_path / "idx", [by] if by else [])
    want = {g.name: g for g in logs.groups} or {"all": logs.overall}
    got = {g.name: g for g in index.groups} or {"all": index.overall}
    assert set(want) == set(got)
    for name, a in want.items():
        b = got[name]
        for count in ("decisions", "sealed", "gaps", "fully_traceable", "reconstructable",
                      "integrity_ok", "missing_cycles", "declared_dropped", "factors"):  # fmt: skip
            assert getattr(a, count) == getattr(b, count), (name, count)
        assert b.tc == pytest.approx(a.tc, abs=1e-12)
        assert b.dr == pytest.approx(a.dr, abs=1e-12)
        for stat in ("et", "et_partial", "tcs"):
            assert getattr(b, stat).mean == pytest.approx(getattr(a, stat).mean, abs=1e-12)
            assert getattr(b, stat).std == pytest.approx(getattr(a, stat).std, abs=1e-9)


def test_update_after_compaction_and_new_segments_reads_only_those(
    fleet: Path, tmp_path: Path
) -> None:
    index = tmp_path / "idx"
    first = build_index([fleet], index)
    assert first.unchanged == 0 and len(first.indexed) == first.segments
    again = build_index([fleet], index)
    assert again.indexed == () and again.unchanged == first.segments

    compact(fleet, "cold", older_than_ns=0, robot="r1")
    r1_files = sorted(p.name for p in (fleet / "cold").glob("r1_*.mcap"))
    after = build_index([fleet], index)
    assert sorted(Path(p).name for p in after.indexed) == r1_files
    assert all("/cold/" in p for p in after.indexed)
    assert _per_robot(index) == {"r1": 100, "r2": 97}
    # The hot copies' rows are gone, not doubled: every r1 row names a cold file now.
    tiers = run_query(index, "SELECT DISTINCT tier FROM decisions WHERE robot = 'r1'").rows
    assert tiers == [("cold",)]

    r2_before = {p.name for p in (fleet / "hot").glob("r2_*.mcap")}
    write_log(fleet, robot_id="r2", max_segment_s=4.0, t0_ns=T0_NS + 60_000_000_000)
    new = {p.name for p in (fleet / "hot").glob("r2_*.mcap")} - r2_before
    later = build_index([fleet], index)
    assert {Path(p).name for p in later.indexed} == new
    assert _per_robot(index) == {"r1": 100, "r2": 197}
    assert index_metrics(index).overall.decisions == compute_metrics([fleet]).overall.decisions


def test_find_stop_near_a_person_links_back_to_explain(fleet: Path, tmp_path: Path) -> None:
    build_index([fleet], tmp_path / "idx")
    found = find_decisions(tmp_path / "idx", action="STOP", near="person", within_m=2.0)
    records = found.records()
    assert records, "the fixture stops for a person 1.5 m away"
    for row in records:
        assert row["command"] == "STOP" and row["nearest_m"] < 2.0
        assert row["nearest_class"] == "person"
    # The decision's nearest-person figure is the entities table's, for every row found.
    nearest = run_query(
        tmp_path / "idx",
        "SELECT robot, cycle, min(distance) FROM entities WHERE class = 'person' GROUP BY ALL",
    ).rows
    by_cycle = {(r, c): m for r, c, m in nearest}
    assert all(by_cycle[row["robot"], row["cycle"]] == row["nearest_m"] for row in records)
    expected = sum(
        1
        for r in run_query(tmp_path / "idx", "SELECT robot, cycle, command FROM decisions").rows
        if r[2] == "STOP" and by_cycle.get((r[0], r[1]), 99.0) < 2.0
    )
    assert len(records) == expected
    first = records[0]
    command = first["explain"].split()
    assert command[:2] == ["trace-audit", "explain"]
    done = subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", *command[1:], "--json"],
        capture_output=True,
        text=True,
        check=True,
        cwd=REPO,
    )
    explained = json.loads(done.stdout)
    assert explained["cycle"] == first["cycle"]


def test_sql_errors_are_one_clean_line_with_exit_2(fleet: Path, tmp_path: Path) -> None:
    build_index([fleet], tmp_path / "idx")
    with pytest.raises(UsageError, match=r"^SQL: "):
        run_query(tmp_path / "idx", "SELECT nope FROM decisions")
    done = subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", "query", str(tmp_path / "idx"), "SELEC 1"],
        capture_output=True,
        text=True,
        check=False,
        cwd=REPO,
    )
    assert done.returncode == 2
    assert done.stdout == ""
    assert re.fullmatch(r"trace-audit: SQL: [^\n]+\n", done.stderr)


def test_a_directory_that_is_not_an_index_is_refused(fleet: Path, tmp_path: Path) -> None:
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    with pytest.raises(UsageError, match="not a fleet index"):
        build_index([fleet], other)
    assert (other / "notes.txt").read_text() == "keep me"
    with pytest.raises(LogReadError, match="not a fleet index"):
        run_query(other, "SELECT 1")
    assert not (other / MANIFEST).exists()


def test_every_column_is_documented_in_docs_fleet() -> None:
    text = (REPO / "docs" / "fleet.md").read_text(encoding="utf-8")
    for table in TABLES:
        section = text.split(f"### `{table}`", 1)[1].split("\n### ", 1)[0]
        for name in schema(table).names:
            assert f"| `{name}` |" in section, f"{table}.{name} is not documented"


def test_an_index_of_another_version_is_rebuilt_in_place(fleet: Path, tmp_path: Path) -> None:
    """Every row is re-read, and the old version's listed files go; a file its manifest
    does not list is not provably the index's: it is left alone, and not read either."""
    index = tmp_path / "idx"
    build_index([fleet], index)
    manifest = json.loads((index / MANIFEST).read_text())
    manifest["version"] = 0
    (index / MANIFEST).write_text(json.dumps(manifest))
    day = index / "decisions" / "robot=r1" / "day=run-000000"
    stray = day / "from-version-0.parquet"
    shutil.copy(sorted(day.glob("*.parquet"))[0], stray)
    report = build_index([fleet], index)
    assert len(report.indexed) == report.segments and report.unchanged == 0
    assert stray.exists()
    assert _per_robot(index) == {"r1": 100, "r2": 97}


def test_metrics_and_the_index_count_a_segment_and_its_truncated_copy_once(
    tmp_path: Path,
) -> None:
    """A root holding a segment and, beside it, a copy cut in half: ``metrics`` counts each
    cycle once, as the index does, and as the root without the copy."""
    root = write_log(tmp_path / "root", robot_id="r1")
    alone = compute_metrics([root]).overall.decisions
    original = root / "hot" / "r1_000000.mcap"
    (root / "hot" / "copy").mkdir()
    half = root / "hot" / "copy" / original.name
    half.write_bytes(original.read_bytes()[: original.stat().st_size // 2])
    report = build_index([root], tmp_path / "idx")
    assert compute_metrics([root]).overall.decisions == alone
    assert compute_metrics([half, original]).overall.decisions == alone
    assert report.decisions_total == alone
    assert index_metrics(tmp_path / "idx", []).overall.decisions == alone
