"""An index folder someone sent: a manifest that names files outside the folder, links
planted where the index writes, a manifest that is a FIFO or nested too deep, a second run
at the same time, a folder a killed run left half built. Nothing outside the folder is read,
written or deleted; every refusal is one line with the documented exit code."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from tests.outside import cli, one_line, snapshot
from tests.trace_audit.conftest import write_log
from trace_audit.fleet.folder import LOCK
from trace_audit.fleet.index import MANIFEST, build_index
from trace_audit.fleet.query import run_query
from trace_runtime.boundary import folder_lock
from trace_runtime.errors import UnsafePathError

SECRET = "the victim's own words\n"


@pytest.fixture()
def built(tmp_path: Path) -> tuple[Path, Path]:
    """A log root and an index of it."""
    root = write_log(tmp_path / "logs", robot_id="r1", max_segment_s=3.0)
    done = cli("index", root, "--out", tmp_path / "idx")
    assert done.returncode == 0, done.stderr
    return root, tmp_path / "idx"


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "victim.txt"
    victim.write_text(SECRET, encoding="utf-8")
    return victim


def _forge(index: Path, name: str, *, stale: bool) -> None:
    """Add ``name`` to the first segment's file list; ``stale`` makes its digest wrong, so
    an update would re-index the segment and delete the files it no longer writes."""
    manifest = json.loads((index / MANIFEST).read_text(encoding="utf-8"))
    entry = next(iter(manifest["segments"].values()))
    entry["files"].append(name)
    if stale:
        entry["sha256"] = "0" * 64
        manifest["digests"] = {}
    (index / MANIFEST).write_text(json.dumps(manifest), encoding="utf-8")


@pytest.mark.parametrize("how", ["absolute", "dotdot"])
def test_a_manifest_naming_a_file_outside_is_refused_and_the_file_stays(
    built: tuple[Path, Path], tmp_path: Path, how: str
) -> None:
    root, index = built
    victim = _victim(tmp_path)
    _forge(index, str(victim) if how == "absolute" else "../victim.txt", stale=True)
    before = snapshot(index)
    done = cli("index", root, "--out", index)
    one_line(done, 3, "index.json", "refused")
    assert victim.read_text(encoding="utf-8") == SECRET
    assert snapshot(index) == before


def test_a_manifest_cannot_widen_what_a_query_may_read(
    built: tuple[Path, Path], tmp_path: Path
) -> None:
    _, index = built
    victim = _victim(tmp_path)
    _forge(index, str(victim), stale=False)
    done = cli("query", index, f"SELECT * FROM read_text('{victim}')", "--json")
    one_line(done, 3, "index.json")
    assert "victim's own words" not in done.stdout + done.stderr


def test_links_planted_where_the_index_writes_are_not_followed(tmp_path: Path) -> None:
    """At the names the index would write aside (this process's id, the first counts) and
    the names older versions used: every victim keeps its bytes, and the index is whole."""
    root = write_log(tmp_path / "logs", robot_id="r1", max_segment_s=3.0)
    index = tmp_path / "idx"
    first = build_index([root], index)
    victims = []
    names = [f".{MANIFEST}.{os.getpid()}.{n}.partial" for n in range(3)] + [MANIFEST + ".partial"]
    for rel in sorted(p.relative_to(index).as_posix() for p in index.rglob("*.parquet")):
        folder, name = rel.rsplit("/", 1)
        names += [f"{folder}/.{name}.{os.getpid()}.{n}.partial" for n in range(3)]
        names.append(rel + ".partial")
    for i, name in enumerate(names):
        victim = tmp_path / "victims" / f"{i}.txt"
        victim.parent.mkdir(exist_ok=True)
        victim.write_text(SECRET, encoding="utf-8")
        (index / name).symlink_to(victim)
        victims.append(victim)
    manifest = json.loads((index / MANIFEST).read_text(encoding="utf-8"))
    for entry in manifest["segments"].values():
        entry["sha256"] = "0" * 64  # every segment is written again
    manifest["digests"] = {}
    (index / MANIFEST).write_text(json.dumps(manifest), encoding="utf-8")
    again = build_index([root], index)
    assert again.decisions_written == first.decisions_total > 0
    assert all(v.read_text(encoding="utf-8") == SECRET for v in victims)
    assert run_query(index, "SELECT count(*) FROM decisions").rows == [(first.decisions_total,)]


def test_a_table_folder_linked_elsewhere_is_refused(tmp_path: Path) -> None:
    root = write_log(tmp_path / "logs", robot_id="r1")
    index = tmp_path / "idx"
    build_index([root], index)
    elsewhere = tmp_path / "elsewhere"
    (index / "decisions").rename(elsewhere)
    (index / "decisions").symlink_to(elsewhere)
    before = snapshot(elsewhere)
    with pytest.raises(UnsafePathError):
        build_index([root], index)
    assert snapshot(elsewhere) == before
    done = cli("query", index, "SELECT count(*) FROM decisions")
    one_line(done, 3, "refused")


@pytest.mark.parametrize("what", ["fifo", "deep", "huge"])
def test_a_manifest_that_is_a_fifo_deep_or_huge_isone_line(
    built: tuple[Path, Path], what: str
) -> None:
    root, index = built
    manifest = index / MANIFEST
    manifest.unlink()
    if what == "fifo":
        os.mkfifo(manifest)
    elif what == "deep":
        manifest.write_text("[" * 200_000 + "]" * 200_000, encoding="utf-8")
    else:
        with manifest.open("wb") as f:  # sparse: larger than any manifest may be
            f.truncate(65 * 2**20)
    for args in (("index", root, "--out", index), ("query", index, "SELECT 1")):
        one_line(cli(*args), 3, "index.json")


def test_a_second_index_run_at_the_same_time_is_refused(built: tuple[Path, Path]) -> None:
    root, index = built
    with folder_lock(index / LOCK, held="held by this test"):
        before = snapshot(index)  # with the lock file this test made
        done = cli("index", root, "--out", index)
    one_line(done, 2, "another index run")
    assert snapshot(index) == before


def test_a_folder_a_killed_run_left_without_a_manifest_is_rebuilt(
    built: tuple[Path, Path],
) -> None:
    """Parquet files and partial files, no manifest: provably the index's own, rebuilt in
    place; a file of anyone else's beside them makes the folder not ours (refused)."""
    root, index = built
    total = run_query(index, "SELECT count(*) FROM decisions").rows[0][0]
    (index / MANIFEST).unlink()
    (index / f".{MANIFEST}.999999.0.partial").write_text("{", encoding="utf-8")
    done = cli("index", root, "--out", index, "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["decisions_written"] == total
    assert run_query(index, "SELECT count(*) FROM decisions").rows == [(total,)]

    (index / MANIFEST).unlink()
    (index / "notes.txt").write_text(SECRET, encoding="utf-8")
    before = snapshot(index)
    one_line(cli("index", root, "--out", index), 2, "not a fleet index")
    assert snapshot(index) == before
