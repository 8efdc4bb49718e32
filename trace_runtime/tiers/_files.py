"""Crash-safe file steps: write aside and rename, fsync directories, one compactor per root."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

from trace_runtime.errors import UsageError

PARTIAL_SUFFIX = ".partial"
LOCK_NAME = ".compact.lock"


def fsync_dir(directory: Path) -> None:
    """Make a rename or unlink in ``directory`` durable (no-op where unsupported)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data``: write a sibling, fsync it, rename it over, fsync the dir."""
    tmp = path.with_name(path.name + PARTIAL_SUFFIX)
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    fsync_dir(path.parent)


def partial_path(target: Path) -> Path:
    """Where a segment is written before it is verified and renamed to ``target``."""
    return target.with_name(target.name + PARTIAL_SUFFIX)


@contextlib.contextmanager
def root_lock(root: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``root`` for one compaction (released even on kill -9)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock, compaction stays correct when run alone
        yield
        return
    fd = os.open(root / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as err:
            raise UsageError(f"{root}: another compaction is running on this log root") from err
        yield
    finally:
        os.close(fd)
