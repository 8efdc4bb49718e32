"""``trace-audit verify`` in an 80-column terminal: a finding's message reads as sentences,
not a word or two a line, however wide the cells beside it (a wall clock's times, a long
robot name); text as plain output and on a terminal (rich, through a pseudo-terminal)."""

from __future__ import annotations

import json
import os
import pty
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import REPO, cli
from tests.trace_audit.conftest import write_log

WALL_T0_NS = 1_714_564_800_000_000_000  # 2024-05-01T12:00:00Z
ROBOT = "warehouse-amr-0007"


@pytest.fixture(scope="module")
def damaged(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A root on a wall clock whose second segment was deleted (a missing_segment finding)."""
    root = tmp_path_factory.mktemp("layout") / "root"
    write_log(root, t0_ns=WALL_T0_NS, robot_id=ROBOT, max_segment_s=3.0)
    (root / "hot" / f"{ROBOT}_000001.mcap").unlink()
    return root


def _messages(root: Path) -> list[str]:
    report = json.loads(cli("verify", root, "--json").stdout)
    messages = [f["message"] for f in report["findings"] + report["notes"]]
    assert any("missing" in m for m in messages), messages
    return messages


def _assert_sentences(text: str, messages: list[str]) -> None:
    """Each message's first 25 characters stand on one line of ``text`` (the old layout
    wrapped it at 16)."""
    lines = [re.sub(r"\s+", " ", line).strip() for line in text.splitlines()]
    for message in messages:
        head = message[:25]
        assert any(head in line for line in lines), (head, text)


def test_plain_text_at_80_columns(damaged: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", "verify", str(damaged), "--plain"],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "80"},
        timeout=120,
    )
    assert done.returncode == 1, done.stderr
    _assert_sentences(done.stdout, _messages(damaged))


def test_a_terminal_of_80_columns(damaged: Path) -> None:
    leader, follower = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "trace_audit.cli", "verify", str(damaged)],
        stdout=follower,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": str(REPO), "COLUMNS": "80", "TERM": "dumb"},
    )
    os.close(follower)
    chunks: list[bytes] = []
    while True:
        try:
            chunk = os.read(leader, 65536)
        except OSError:  # the terminal closed with the process
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(leader)
    assert proc.wait(60) == 1
    text = re.sub(r"\x1b\[[0-9;]*m", "", b"".join(chunks).decode())
    _assert_sentences(text, _messages(damaged))
