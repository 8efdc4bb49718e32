"""Helpers for the logger's storage tests: cycles logged at 10 Hz, a script run as a robot."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from trace_runtime import AuditLogger
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000
WORKTREE = Path(__file__).resolve().parents[2]


def log_cycles(logger: AuditLogger, numbers: range) -> None:
    for i in numbers:
        p, b, a, e = synthetic_cycle(i)
        logger.log_cycle(i * PERIOD_NS, perception=p, belief=b, action=a, execution=e)


def spawn(script: str, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(WORKTREE)}
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
