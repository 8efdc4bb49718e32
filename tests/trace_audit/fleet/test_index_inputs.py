"""``index`` against inputs and index directories that disagree with themselves: two logs
at one chain position, a truncated copy beside the intact file, Parquet files gone or
damaged, a corrupt manifest. Run from the outside: the CLI in a subprocess, real files."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from tests.outside import cli
from tests.trace_audit.conftest import T0_NS, write_log
from trace_audit.fleet.index import MANIFEST


def _count(index: Path, where: str = "true") -> int:
    done = cli("query", index, f"SELECT count(*) AS n FROM decisions WHERE {where}", "--json")
    assert done.returncode == 0, done.stderr
    return int(json.loads(done.stdout)[0]["n"])


def _index(*args: str | Path) -> dict[str, object]:
    done = cli("index", *args, "--json")
    assert done.returncode == 0, done.stderr
    report: dict[str, object] = json.loads(done.stdout)
    return report


def test_two_logs_of_one_robot_at_one_position_are_refused(tmp_path: Path) -> None:
    """Two roots whose robot has the same id, each starting at segment 0, cycle 0: both
    are named in one line, exit 2, and an existing index keeps its rows."""
    write_log(tmp_path / "a", robot_id="amr-01")
    write_log(tmp_path / "b", robot_id="amr-01", t0_ns=T0_NS + 7_000_000_000, skip=lambda i: i == 3)
    done = cli("index", tmp_path / "a", tmp_path / "b", "--out", tmp_path / "both")
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1
    assert "a/hot/amr-01_000000.mcap" in done.stderr and "b/hot/amr-01_000000.mcap" in done.stderr
    assert not (tmp_path / "both" / MANIFEST).exists()

    first = _index(tmp_path / "a", "--out", tmp_path / "idx")
    before = _count(tmp_path / "idx")
    assert before == first["decisions_total"] > 0
    done = cli("index", tmp_path / "b", "--out", tmp_path / "idx")
    assert done.returncode == 2, done.stderr
    assert "a/hot/amr-01_000000.mcap" in done.stderr
    assert _count(tmp_path / "idx") == before


def test_an_intact_segment_beats_its_truncated_copy(tmp_path: Path) -> None:
    """A half-copied file beside the original: the intact copy is indexed, whichever
    order they are given in, the copy left out is named, and the totals agree."""
    intact = write_log(tmp_path / "arm.mcap", robot_id="arm-1")
    (tmp_path / "bad").mkdir()
    half = tmp_path / "bad" / "trunc.mcap"
    half.write_bytes(intact.read_bytes()[: intact.stat().st_size // 2])
    alone = _index(intact, "--out", tmp_path / "alone")
    for order, name in (((half, intact), "i1"), ((intact, half), "i2")):
        report = _index(*order, "--out", tmp_path / name)
        assert report["decisions_total"] == report["decisions_written"] == alone["decisions_total"]
        assert report["indexed"] == [str(intact.resolve())]
        assert any(str(half) in note for note in report["notes"]), report["notes"]  # type: ignore[union-attr]
        assert _count(tmp_path / name) == alone["decisions_total"]
    # The truncated copy added to an index of the intact file replaces nothing.
    again = _index(half, "--out", tmp_path / "alone")
    assert again["decisions_written"] == 0
    assert _count(tmp_path / "alone") == alone["decisions_total"]


def test_a_missing_or_damaged_parquet_file_is_indexed_again(tmp_path: Path) -> None:
    root = write_log(tmp_path / "logs", robot_id="r1", max_segment_s=3.0)
    first = _index(root, "--out", tmp_path / "idx")
    total = first["decisions_total"]
    files = sorted((tmp_path / "idx" / "decisions").rglob("*.parquet"))
    assert len(files) >= 2
    files[0].unlink()
    files[1].write_bytes(b"PAR1 not really")
    report = _index(root, "--out", tmp_path / "idx")
    assert len(report["indexed"]) == 2  # type: ignore[arg-type]
    assert report["decisions_total"] == total
    assert _count(tmp_path / "idx") == total


def test_a_corrupt_manifest_is_refused_and_nothing_is_deleted(tmp_path: Path) -> None:
    root = write_log(tmp_path / "logs", robot_id="r1", max_segment_s=3.0)
    _index(root, "--out", tmp_path / "idx")
    files = sorted(p for p in (tmp_path / "idx").rglob("*") if p.is_file())
    (tmp_path / "idx" / MANIFEST).write_text("{", encoding="utf-8")
    other = write_log(tmp_path / "mini.mcap", robot_id="mini")
    done = cli("index", other, "--out", tmp_path / "idx")
    assert done.returncode == 3, done.stderr
    assert done.stderr.count("\n") == 1 and "index.json" in done.stderr
    assert sorted(p for p in (tmp_path / "idx").rglob("*") if p.is_file()) == files


def test_a_manifest_of_another_version_is_rebuilt_in_place(tmp_path: Path) -> None:
    """An index of an older version is provably ours (its manifest says so): rebuilt."""
    root = write_log(tmp_path / "logs", robot_id="r1")
    first = _index(root, "--out", tmp_path / "idx")
    manifest = json.loads((tmp_path / "idx" / MANIFEST).read_text(encoding="utf-8"))
    manifest["version"] = 0
    (tmp_path / "idx" / MANIFEST).write_text(json.dumps(manifest), encoding="utf-8")
    shutil.copy(tmp_path / "idx" / MANIFEST, tmp_path / "old.json")
    again = _index(root, "--out", tmp_path / "idx")
    assert again["decisions_written"] == first["decisions_total"]
    assert _count(tmp_path / "idx") == first["decisions_total"]


def test_metrics_from_the_index_says_what_the_index_does_not_hold(tmp_path: Path) -> None:
    """--failures and --evidence need the logs (one line, exit 2); the failing count is the
    logs' count, and timing, channels and external refs say "not in the index"."""
    root = write_log(tmp_path / "logs", robot_id="r1", max_segment_s=3.0)
    _index(root, "--out", tmp_path / "idx")
    for extra in (["--failures"], ["--evidence", str(tmp_path)]):
        done = cli("metrics", "--index", tmp_path / "idx", *extra)
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1 and "index" in done.stderr
    logs = json.loads(cli("metrics", root, "--json").stdout)
    index = json.loads(cli("metrics", "--index", tmp_path / "idx", "--json").stdout)
    assert logs["failures_total"] > 0
    assert index["failures_total"] == logs["failures_total"]
    assert index["gaps_total"] == logs["gaps_total"]
    assert "not in the index" in index["logging_time"]
    assert set(index["not_in_index"]) >= {"logging_cost", "channel_deviation", "external_refs"}
    assert "not_in_index" not in logs
    text = cli("metrics", "--index", tmp_path / "idx", "--plain").stdout
    assert "not in the index" in text and "not logged" not in text
