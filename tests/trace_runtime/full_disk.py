"""Helpers for the full-disk tests: a disk (``LoggerConfig.opener``) that fills at a chosen
write and lands part of it, a tiny real tmpfs mounted for one test, and the check that a
log written through either holds what the logger's counters say, with no finding."""

from __future__ import annotations

import errno
import io
import os
import random
import shutil
import subprocess
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import pytest

from trace_runtime import AuditLogger, LoggerConfig, LoggerStats, open_log
from trace_runtime.errors import LogReadError
from trace_runtime.testing import synthetic_cycle
from trace_runtime.verification import verify


@dataclass
class FullDisk:
    """A disk that fills at write number ``fails_at`` (counted over every file opened on it).

    That write lands ``lands(length)`` bytes of its data in the file, then raises ENOSPC;
    the next ``stays_full`` writes land nothing and raise too; then the disk has room again.
    Truncating (the writer's rollback) raises ENOSPC unless ``rollback_works``.
    """

    fails_at: int
    lands: Callable[[int], int]
    stays_full: int = 0
    rollback_works: bool = False
    writes: int = 0

    def open(self, path: Path) -> BinaryIO:
        """The ``LoggerConfig.opener`` of this disk."""
        return _FullDiskFile(path, self)


class _FullDiskFile(io.FileIO):
    def __init__(self, path: Path, disk: FullDisk) -> None:
        super().__init__(path, "w")
        self.disk = disk

    def write(self, data: Any) -> int:
        disk = self.disk
        disk.writes += 1
        if disk.writes == disk.fails_at:
            super().write(bytes(data)[: disk.lands(len(data))])
        elif not disk.fails_at < disk.writes <= disk.fails_at + disk.stays_full:
            return super().write(data)
        raise OSError(errno.ENOSPC, "No space left on device")

    def truncate(self, size: Any = None) -> int:
        if not self.disk.rollback_works:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().truncate(size)


def assert_log_agrees(root: Path, stats: LoggerStats) -> None:
    """``verify`` finds nothing (declared drops are notes), and every cycle in the files is
    counted as written, every other committed cycle as dropped. A disk that never took a
    cycle leaves no decision to verify: every cycle is counted as dropped."""
    if stats.written == 0:
        assert stats.dropped == stats.committed, stats
        assert not any(c.sealed for c in _cycles_if_any(root)), stats
        return
    log = open_log(root)
    report = verify(log)
    findings = [f"{f.kind}: {f.message}" for f in report.findings]
    assert not findings, findings
    in_files = sum(1 for _ in log.iter_cycles())
    assert stats.written == in_files, f"{in_files} cycles in the files, {stats}"
    assert stats.written + stats.dropped == stats.committed, stats


def robot_cycle(cycle: Any, i: int) -> None:
    """A robot's cycle: a few sensor readings (each its own channel) and the four layers."""
    for topic in ("/sensors/lidar", "/sensors/sonar", "/sensors/odom")[: 1 + i % 3]:
        cycle.sensor(topic, {"i": i, "v": [i / 7, i / 11]})
    p, b, a, e = synthetic_cycle(i)
    cycle.perception(p)
    cycle.belief(b)
    cycle.action(a)
    cycle.execution(e)


def fill_tmpfs(disk: Path, root: Path, rng: random.Random, cycles: int = 1200) -> LoggerStats:
    """A robot (the threaded logger, as robots run it) logs ``cycles`` into ``root`` on a
    2 MiB ``disk`` that ballast of 1-1.3 MiB fills; the ballast is deleted some cycles after
    the first drop (or never), and the robot goes on. The logger's stats."""
    ballast = disk / "ballast"
    ballast.write_bytes(os.urandom(1024 * 1024 + rng.randrange(300_000)))
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(checkpoint_interval_s=1.0))
    free_after = rng.choice([None, 1, 20, 60])
    first_drop: int | None = None

    def each(cycle: Any, i: int) -> None:
        nonlocal first_drop
        for k in range(rng.randrange(1, 12)):  # many small channels: many message indexes
            cycle.sensor(f"/sensors/s{k}", {"x": os.urandom(rng.randrange(4, 40)).hex()})
        robot_cycle(cycle, i)
        if first_drop is None and logger.stats.dropped_io:
            first_drop = i
        if free_after is not None and first_drop is not None and i == first_drop + free_after:
            ballast.unlink()

    run_logger(logger, cycles, each)
    ballast.unlink(missing_ok=True)
    return logger.stats


def run_logger(logger: AuditLogger, cycles: int, each: Callable[[Any, int], None]) -> None:
    """``cycles`` cycles at 10 Hz, ``each(cycle_builder, i)`` filling cycle ``i``."""
    for i in range(cycles):
        with logger.cycle(i * 100_000_000) as cycle:
            each(cycle, i)
    logger.close()


@contextmanager
def tiny_tmpfs(where: Path, size: str = "2m") -> Iterator[Path]:
    """A tmpfs of ``size`` mounted at ``where`` for the block, unmounted after it; skips the
    test where that cannot be done (not root, no ``mount``, no tmpfs in this container)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root and mount(8)")
    where.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip()}")
    try:
        yield where
    finally:
        # A failed test's traceback may still hold a reader's open file: detach lazily then.
        if subprocess.run(["umount", str(where)], capture_output=True, check=False).returncode:
            subprocess.run(["umount", "-l", str(where)], check=True)


def _cycles_if_any(root: Path) -> list[Any]:
    """The cycles in ``root``'s files, none when no file holds a readable segment."""
    try:
        return list(open_log(root).iter_cycles())
    except LogReadError:
        return []
