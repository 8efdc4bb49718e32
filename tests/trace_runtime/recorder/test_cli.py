"""``trace-recorder`` as a program: its help, one line on stderr and a documented exit code
for each way it cannot start, and a stale socket of a killed recorder replaced."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import one_line
from tests.trace_runtime.recorder.conftest import RecorderProcess
from trace_runtime.errors import EXIT_CANNOT_WRITE, EXIT_OK, EXIT_USAGE

REPO = Path(__file__).resolve().parents[3]


def _program(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "trace_runtime.recorder.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )


def test_help_names_every_option_and_the_exit_codes() -> None:
    done = _program("serve", "--help")
    assert done.returncode == EXIT_OK
    for needle in ("--root", "--socket", "--tcp", "--key", "--witness", "0660", "exit codes"):
        assert needle in done.stdout


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["serve", "--root", "r"], "--socket"),
        (["serve", "--root", "r", "--socket", "s", "--tcp", "10.0.0.1:7400"], "loopback"),
        (["serve", "--root", "r", "--socket", "s", "--tcp", "localhost"], "HOST:PORT"),
        (["serve", "--root", "r", "--socket", "s", "--witness", "http://w"], "needs --key"),
        (["serve", "--root", "r", "--socket", "s", "--key", "missing.key"], "no such file"),
    ],
)
def test_a_bad_invocation_is_one_line_and_exit_2(
    args: list[str], needle: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    one_line(_program(*args), EXIT_USAGE, needle)


def test_a_socket_path_that_is_a_file_is_not_replaced(tmp_path: Path) -> None:
    taken = tmp_path / "rec.sock"
    taken.write_text("not a socket")
    done = _program("serve", "--root", tmp_path / "root", "--socket", taken)
    one_line(done, EXIT_CANNOT_WRITE, "not a socket")
    assert taken.read_text() == "not a socket"


def test_a_live_recorder_s_socket_is_not_taken_over(recorder: RecorderProcess) -> None:
    done = _program("serve", "--root", recorder.root, "--socket", recorder.socket)
    one_line(done, EXIT_USAGE, "another recorder is listening")
    code, _ = recorder.stop()
    assert code == EXIT_OK
    assert not recorder.socket.exists()  # removed at a clean stop


def test_a_killed_recorder_s_stale_socket_is_replaced(tmp_path: Path) -> None:
    stale = tmp_path / "rec.sock"
    left = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    left.bind(str(stale))
    left.close()  # the file stays, nobody listens: what kill -9 leaves
    process = RecorderProcess(tmp_path / "root", stale).start()
    try:
        probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        probe.connect(str(stale))
        probe.close()
    finally:
        code, _ = process.stop()
    assert code == EXIT_OK
