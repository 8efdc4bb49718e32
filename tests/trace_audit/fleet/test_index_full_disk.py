"""``index`` into a disk that fills (a small real tmpfs, ballast of several sizes) and into
a read-only file system, run from the outside: one line and exit 4 each time, no partial
file and no lock file left, nothing a later ``query`` trusts, and once the disk has room
again the next run builds the whole index."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import write_log
from tests.trace_runtime.full_disk import tiny_tmpfs
from trace_audit.fleet.folder import LOCK

COUNT = "SELECT count(*) AS n FROM decisions"


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(tmp_path_factory.mktemp("full") / "logs", robot_id="r1", max_segment_s=3.0)


def _leftovers(index: Path) -> list[str]:
    """Names a failed run must not leave: its lock and any partial file."""
    if not index.exists():
        return []
    return [
        p.relative_to(index).as_posix()
        for p in index.rglob("*")
        if p.name == LOCK or p.name.endswith(".partial")
    ]


@pytest.mark.parametrize("free_kib", [4, 24, 60, 100, 120, 130])
def test_an_index_into_a_full_disk_is_one_line_exit_4(
    logs: Path, tmp_path: Path, free_kib: int
) -> None:
    """From no room for a single table file to room for all but the manifest (130 KiB on
    this tmpfs; 140 KiB hold the whole index)."""
    with tiny_tmpfs(tmp_path / "disk", size="512k") as disk:
        ballast = disk / "ballast"
        ballast.write_bytes(os.urandom((512 - free_kib) * 1024))
        index = disk / "idx"
        one_line(cli("index", logs, "--out", index), 4, "cannot write", "No space left")
        assert _leftovers(index) == []
        one_line(cli("query", index, COUNT), 3)
        ballast.unlink()
        rebuilt = cli("index", logs, "--out", index, "--json")
        assert rebuilt.returncode == 0, rebuilt.stderr
        assert _leftovers(index) == []
        counted = cli("query", index, COUNT, "--csv")
        assert counted.returncode == 0, counted.stderr
        assert counted.stdout.split() == ["n", "100"], counted.stdout


def test_an_update_into_a_full_disk_keeps_the_index_it_had(logs: Path, tmp_path: Path) -> None:
    """A second root indexed into an index whose disk filled: the index still answers for
    the first root, whole."""
    other = write_log(tmp_path / "other", robot_id="r2", max_segment_s=3.0)
    with tiny_tmpfs(tmp_path / "disk", size="512k") as disk:
        index = disk / "idx"
        assert cli("index", logs, "--out", index).returncode == 0
        free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
        (disk / "ballast").write_bytes(os.urandom(max(0, free - 40 * 1024)))
        one_line(cli("index", logs, other, "--out", index), 4, "cannot write")
        assert _leftovers(index) == []
        counted = cli("query", index, COUNT, "--csv")
        assert counted.returncode == 0, counted.stderr
        assert counted.stdout.split() == ["n", "100"], counted.stdout


def test_an_index_into_a_read_only_file_system_is_exit_4(logs: Path, tmp_path: Path) -> None:
    """A new folder under it, an empty folder in it, and the read-only folder itself: the
    write it cannot make is what the user hears (root ignores file modes: a mount)."""
    with tiny_tmpfs(tmp_path / "ro", size="64k") as ro:
        (ro / "empty").mkdir()
        (ro / "notes.txt").write_text("the archive's own file\n", encoding="utf-8")
        subprocess.run(["mount", "-o", "remount,ro", str(ro)], check=True)
        for out in (ro / "idx", ro / "empty", ro):
            one_line(cli("index", logs, "--out", out), 4, "cannot write")


def test_a_worker_process_that_meets_a_full_disk_is_one_line_exit_4(
    logs: Path, tmp_path: Path
) -> None:
    """The error crosses back from a local worker process, pickled, as the same one line."""
    with tiny_tmpfs(tmp_path / "disk", size="512k") as disk:
        (disk / "ballast").write_bytes(os.urandom((512 - 24) * 1024))
        index = disk / "idx"
        one_line(cli("index", logs, "--out", index, "--jobs", "2"), 4, "No space left")
        assert _leftovers(index) == []
