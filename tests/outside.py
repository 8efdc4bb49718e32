"""Running the CLI from the outside, as a user does: a fresh process of this checkout, and
what a test checks of it (one line on stderr, the files a folder holds)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def cli(*args: str | Path, timeout_s: float = 120) -> subprocess.CompletedProcess[str]:
    """``trace-audit ARGS`` in a fresh process; a run that blocks (on a FIFO, say) fails
    the test at ``timeout_s`` instead of hanging the suite."""
    return subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=timeout_s,
    )


def one_line(done: subprocess.CompletedProcess[str], code: int, *needles: str) -> None:
    """The run ended with ``code`` and exactly one stderr line holding every needle."""
    assert done.returncode == code, (done.returncode, done.stderr)
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
    for needle in needles:
        assert needle in done.stderr, done.stderr


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every regular file under ``folder`` (not through links), by relative name, with its
    bytes: compared before and after, it shows whether a command touched anything."""
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.is_symlink()
    }
