"""A log root someone sent: tier folders and side files that are links, FIFOs where files
belong, a catalog too large or forged, a segment retention must not leave a hole behind, a
root on a read-only disk. Run from the outside (the CLI in a subprocess, real files); the
victims outside the root keep their bytes and every refusal is one line."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.outside import cli, one_line, snapshot
from tests.trace_audit.conftest import T0_NS, write_log
from trace_runtime.tiers.catalog import refresh_catalog

SECRET = b"not the tool's to touch\n"
INSIDE_T = f"{T0_NS / 1e9 + 5.0:.1f}"  # a time inside the fixture log (10 s from t = 100 s)


def _no_traceback(done: subprocess.CompletedProcess[str], code: int) -> None:
    assert done.returncode == code, (done.returncode, done.stderr)
    assert "Traceback" not in done.stderr, done.stderr


@pytest.fixture()
def root(tmp_path: Path) -> Path:
    return write_log(tmp_path / "root", robot_id="r1", max_segment_s=3.0)


@pytest.mark.parametrize("tier", ["hot", "cold"])
def test_a_tier_folder_that_is_a_link_is_refused_by_every_command(
    root: Path, tmp_path: Path, tier: str
) -> None:
    elsewhere = tmp_path / "elsewhere"
    if tier == "hot":
        (root / "hot").rename(elsewhere)
    else:
        elsewhere.mkdir()
    (root / tier).symlink_to(elsewhere, target_is_directory=True)
    before = snapshot(elsewhere)
    for args in (
        ("info", root),
        ("verify", root),
        ("catalog", root),
        ("explain", root, "--t", INSIDE_T),
        ("compact", root, "--tier", "cold", "--older-than", "0"),
    ):
        one_line(cli(*args), 3, "symbolic link")
    assert snapshot(elsewhere) == before


@pytest.mark.parametrize("name", ["catalog.json", "retention.jsonl", ".compact.lock"])
def test_a_side_file_linked_elsewhere_is_never_written_through(
    root: Path, tmp_path: Path, name: str
) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_bytes(SECRET)
    (root / name).symlink_to(victim)
    hot = snapshot(root / "hot")
    one_line(cli("compact", root, "--tier", "cold", "--older-than", "0"), 3, "refused")
    assert victim.read_bytes() == SECRET
    assert snapshot(root / "hot") == hot  # refused before any work
    done = cli("catalog", root, "--refresh")
    assert victim.read_bytes() == SECRET
    _no_traceback(done, 3 if name == "catalog.json" else 0)


def test_links_planted_at_the_catalogs_partial_names_are_not_followed(
    root: Path, tmp_path: Path
) -> None:
    """At the names this process would write aside, and the name older versions used."""
    names = [f".catalog.json.{os.getpid()}.{n}.partial" for n in range(3)] + [
        "catalog.json.partial"
    ]
    victims = []
    for i, name in enumerate(names):
        victim = tmp_path / f"victim-{i}.txt"
        victim.write_bytes(SECRET)
        (root / name).symlink_to(victim)
        victims.append(victim)
    catalog = refresh_catalog(root)
    assert len(catalog.entries) == 4
    assert all(v.read_bytes() == SECRET for v in victims)
    assert json.loads((root / "catalog.json").read_text(encoding="utf-8"))


@pytest.mark.parametrize("name", ["catalog.json", "retention.jsonl"])
def test_a_fifo_where_a_side_file_belongs_blocks_nothing(root: Path, name: str) -> None:
    os.mkfifo(root / name)
    for args in (("info", root), ("explain", root, "--t", INSIDE_T), ("catalog", root)):
        _no_traceback(cli(*args), 0)
    one_line(cli("compact", root, "--tier", "cold", "--older-than", "0"), 3, "FIFO")
    assert sorted(p.name for p in (root / "hot").iterdir()) == [
        f"r1_00000{i}.mcap" for i in range(4)
    ]


@pytest.mark.parametrize("what", ["huge", "deep", "directory"])
def test_a_catalog_too_large_too_deep_or_a_directory_is_ignored(root: Path, what: str) -> None:
    catalog = root / "catalog.json"
    if what == "huge":
        with catalog.open("wb") as f:
            f.truncate(65 * 2**20)
    elif what == "deep":
        catalog.write_text("[" * 200_000 + "]" * 200_000, encoding="utf-8")
    else:
        catalog.mkdir()
    done = cli("catalog", root, "--json")
    _no_traceback(done, 0)
    assert "warning" in done.stderr and "catalog.json" in done.stderr
    assert len(json.loads(done.stdout)["segments"]) == 4
    _no_traceback(cli("explain", root, "--t", INSIDE_T), 0)


def test_a_forged_catalog_is_not_believed(root: Path) -> None:
    """Rows that keep each file's real size and mtime but carry another robot, times and
    digest: explain still answers inside the log, and --refresh puts the truth back."""
    assert cli("catalog", root, "--refresh").returncode == 0
    body = json.loads((root / "catalog.json").read_text(encoding="utf-8"))
    for entry in body["segments"]:
        entry["robot"] = "someone-else"
        entry["start_ns"] += 10**12
        entry["end_ns"] += 10**12
        entry["sha256"] = "0" * 64
    (root / "catalog.json").write_text(json.dumps(body), encoding="utf-8")
    done = cli("explain", root, "--t", INSIDE_T, "--json")
    _no_traceback(done, 0)
    assert cli("catalog", root, "--refresh").returncode == 0
    rows = json.loads((root / "catalog.json").read_text(encoding="utf-8"))["segments"]
    for entry in rows:
        assert entry["robot"] == "r1"
        assert entry["sha256"] == hashlib.sha256((root / entry["path"]).read_bytes()).hexdigest()


def test_retention_leaves_no_hole_behind_a_held_segment(root: Path) -> None:
    """Segment 0 held (a stranger's file at its cold partial name): no later segment of the
    robot is deleted, so verify finds no segment missing."""
    (root / "cold").mkdir()
    (root / "cold" / "r1_000000.mcap.partial").write_text("someone else's\n", encoding="utf-8")
    done = cli("compact", root, "--tier", "cold", "--older-than", "0", "--retention", "0s")
    assert "Traceback" not in done.stderr, done.stderr
    verify = cli("verify", root, "--json")
    assert "missing_segment" not in verify.stdout, verify.stdout
    assert verify.returncode == 0, verify.stdout[-2000:]


def test_a_read_only_root_is_one_line_exit_4(root: Path, tmp_path: Path) -> None:
    """On a file system mounted read-only (what an unprivileged user meets on an archive;
    root ignores file modes, so the test mounts one)."""
    mount = tmp_path / "ro"
    mount.mkdir()
    if shutil.which("mount") is None or os.geteuid() != 0:
        pytest.skip("needs root to mount a read-only file system")
    made = subprocess.run(["mount", "-t", "tmpfs", "tmpfs", str(mount)], check=False)
    if made.returncode != 0:
        pytest.skip("this machine cannot mount a tmpfs")
    try:
        shutil.copytree(root, mount / "root")
        subprocess.run(["mount", "-o", "remount,ro", str(mount)], check=True)
        for args in (
            ("catalog", mount / "root", "--refresh"),
            ("compact", mount / "root", "--tier", "cold", "--older-than", "0"),
        ):
            one_line(cli(*args), 4, "cannot write")
        _no_traceback(cli("verify", mount / "root"), 0)
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)
