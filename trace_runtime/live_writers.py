"""Whether a log is being written right now: where a robot's writer lock lives, and whether
a writer holds it, asked without touching the lock.

A segment without a footer is either *live* (its logger is still writing it) or *recovered*
(the logger died: a crash, a full disk, a kill). The two read the same bytes; what tells them
apart is the writer's lock, which the kernel drops with the process. A reader must never take
that lock, not even shared for an instant: a robot starting at that instant would be refused
its own log. So the lock is looked up in ``/proc/locks`` (Linux), and where that cannot say
(another machine writing a shared disk, no ``/proc``), a segment written to within
``RECENT_WRITE_S`` counts as live.
"""

from __future__ import annotations

import os
import stat
import time
from pathlib import Path

from trace_runtime.session import TIERS

__all__ = ["RECENT_WRITE_S", "is_live", "lock_is_held", "lock_path"]

RECENT_WRITE_S = 10.0
"""A file without a footer written to this recently may still be written (a logger flushes
at least every second by default; ten of them missed is a dead writer)."""

_PROC_LOCKS = Path("/proc/locks")


def lock_path(path: Path, is_root: bool, robot_id: str) -> Path:
    """Where the writer lock of a log lives: per robot in a root, per file otherwise. A file
    written straight into a root's tier directory takes the robot's root lock: it would
    otherwise fork the chain of a logger writing that root."""
    if is_root:
        return path / ".locks" / f"{robot_id}.lock"
    if path.parent.name in TIERS:
        return path.parent.parent / ".locks" / f"{robot_id}.lock"
    return path.with_name(f".{path.name}.lock")


def lock_is_held(path: Path) -> bool | None:
    """Whether some process holds an ``flock`` on the file at ``path``: True or False from
    the kernel's lock table, None when it cannot be told (no such table here)."""
    try:
        status = os.lstat(path)
    except OSError:
        return False  # no lock file: no logger ever locked this log here
    if not stat.S_ISREG(status.st_mode):
        return False  # a link or a FIFO planted at the name is nobody's lock
    try:
        table = _PROC_LOCKS.read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    device = f"{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}:{status.st_ino}"
    for line in table.splitlines():
        fields = line.split()
        # "1: FLOCK  ADVISORY  WRITE 4242 08:01:1234 0 EOF" (a blocked waiter adds "->")
        if "FLOCK" in fields and device in fields:
            return True
    return False


def is_live(segment: Path, robot_id: str, *, now: float | None = None) -> bool:
    """Whether the unfinished ``segment`` of ``robot_id`` is being written: its writer's lock
    is held, or (when locks cannot be seen) it was written to within ``RECENT_WRITE_S``."""
    held = lock_is_held(lock_path(segment, False, robot_id))
    if held is not None:
        return held
    try:
        modified = os.stat(segment).st_mtime
    except OSError:
        return False
    return (time.time() if now is None else now) - modified < RECENT_WRITE_S
