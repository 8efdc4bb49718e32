"""One live writer per robot and log root: the OS file lock an ``AuditLogger`` holds while
it writes (where it lives, and how a reader sees it held, is ``live_writers``)."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Callable
from pathlib import Path

from trace_runtime.boundary import open_lock_file
from trace_runtime.errors import LogLockedError, TraceError

if sys.platform != "win32":  # Linux is the target; elsewhere the writer lock is skipped
    import fcntl

__all__ = ["WriterLock"]

log = logging.getLogger("trace_runtime")


class WriterLock:
    """One live writer per robot and log root: an exclusive ``flock`` on a lock file.

    The kernel drops the lock when the process dies, so ``kill -9`` never leaves a stale
    one. The holder's pid is written into the file for the refusal message. ``flock``
    locks belong to the open file, so a second logger in the same process is refused too.
    """

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self._fd = fd

    @classmethod
    def take(cls, path: Path) -> WriterLock | None:
        """Lock ``path``; raise ``LogLockedError`` when another writer holds it. None where
        the platform or the filesystem has no ``flock`` (logged; the log is then unguarded)."""
        if sys.platform == "win32":
            return None
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = open_lock_file(path)  # a link planted at the name is refused, never truncated
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_pid(fd)
            os.close(fd)
            raise LogLockedError(str(path), holder) from None
        except OSError as err:  # e.g. ENOLCK on a filesystem without locks
            os.close(fd)
            log.warning("cannot lock %s (%s): a second writer would not be refused", path, err)
            return None
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError:
            pass  # the pid is only for the message; the lock itself holds
        return cls(path, fd)

    def renew(self, report: Callable[[str, str], None]) -> None:
        """The lock file was deleted with its directory: lock a new one at the same place,
        so a logger started on the recreated root is still refused."""
        if self._fd < 0:
            return
        try:
            if os.fstat(self._fd).st_nlink > 0:
                return
            fresh = WriterLock.take(self.path)
        except LogLockedError as err:
            report("lock", f"audit log lock lost with its directory and taken by another: {err}")
            return
        except (OSError, TraceError) as err:  # a link planted at the name, a full disk
            report("lock", f"could not renew the audit log lock {self.path}: {err}")
            return
        if fresh is not None:
            os.close(self._fd)
            self._fd, fresh._fd = fresh._fd, -1

    def release(self) -> None:
        """Let go of the lock (closing the descriptor drops it). Idempotent."""
        fd, self._fd = self._fd, -1
        if fd < 0:
            return
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)  # no stale pid for the next reader
        os.close(fd)


def _read_pid(fd: int) -> int | None:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None
