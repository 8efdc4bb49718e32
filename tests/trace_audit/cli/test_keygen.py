"""``trace-audit keygen`` from the outside: a folder it cannot write and a key that exists are
both cannot-write (exit 4, one line), and a witness's key gets no robot-only advice."""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.outside import cli, one_line


@pytest.fixture
def read_only(tmp_path: Path) -> Iterator[Path]:
    """A folder on a file system mounted read-only (root ignores file modes, so it mounts)."""
    mount = tmp_path / "ro"
    mount.mkdir()
    if shutil.which("mount") is None or os.geteuid() != 0:
        pytest.skip("needs root to mount a read-only file system")
    made = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)], check=False
    )
    if made.returncode:
        pytest.skip("this machine cannot mount a tmpfs")
    try:
        (mount / "keys").mkdir()
        subprocess.run(["mount", "-o", "remount,ro", str(mount)], check=True)
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], check=False)


def test_keygen_into_a_read_only_folder_is_exit_4(read_only: Path) -> None:
    one_line(cli("keygen", "--out", read_only / "keys"), 4, "cannot write", str(read_only))
    one_line(cli("keygen", "--out", read_only / "new" / "keys"), 4, "cannot write")
    assert list((read_only / "keys").iterdir()) == []


def test_keygen_onto_an_existing_key_is_exit_4_and_keeps_it(tmp_path: Path) -> None:
    assert cli("keygen", "--out", tmp_path, "--name", "amr-7").returncode == 0
    before = (tmp_path / "amr-7.key").read_bytes()
    one_line(cli("keygen", "--out", tmp_path, "--name", "amr-7"), 4, "amr-7.key", "--force")
    assert (tmp_path / "amr-7.key").read_bytes() == before
    (tmp_path / "amr-8.pub").write_text("someone's public key\n")
    one_line(cli("keygen", "--out", tmp_path, "--name", "amr-8"), 4, "amr-8.pub")
    assert not (tmp_path / "amr-8.key").exists()


def test_a_witness_key_is_not_told_to_stay_on_the_robot(tmp_path: Path) -> None:
    done = cli("keygen", "--out", tmp_path, "--name", "witness", "--plain")
    assert done.returncode == 0, done.stderr
    words = " ".join(done.stdout.split())  # a long tmp path wraps the lines
    assert "on the robot" not in words and "checkpoint key" not in words
    assert "witness serve --key" in words and "witness vkey --cosignature --key" in words
