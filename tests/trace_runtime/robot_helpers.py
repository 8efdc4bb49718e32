"""Helpers for the logger's storage tests: cycles logged at 10 Hz, a script run as a robot."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

from trace_runtime import AuditLogger
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000
WORKTREE = Path(__file__).resolve().parents[2]


def log_cycles(logger: AuditLogger, numbers: range) -> None:
    for i in numbers:
        p, b, a, e = synthetic_cycle(i)
        logger.log_cycle(i * PERIOD_NS, perception=p, belief=b, action=a, execution=e)


LOCK_HOLDER = """
    import sys, time
    from trace_runtime import AuditLogger, LoggerConfig
    from trace_runtime.testing import synthetic_cycle
    log = AuditLogger(sys.argv[1], robot_id="r", config=LoggerConfig(threaded=False))
    for i in range(int(sys.argv[2])):
        p, b, a, e = synthetic_cycle(i)
        log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    print("ready", flush=True)
    time.sleep(60)
"""
"""A robot that logs ``argv[2]`` cycles into ``argv[1]`` as robot ``r``, says ``ready`` and
keeps its log open (and its writer lock held) for a minute: run it with ``spawn``."""


def spawn(script: str, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(WORKTREE)}
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


@contextlib.contextmanager
def lock_holder(root: Path, cycles: int) -> Iterator[subprocess.Popen[str]]:
    """``LOCK_HOLDER`` logging ``cycles`` into ``root``, once it has said ``ready``; killed
    (when still alive) and its pipes closed on the way out."""
    proc = spawn(LOCK_HOLDER, str(root), str(cycles))
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready", proc.stderr
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
