"""The logger's storage failures seen from outside: a log root deleted under a running robot,
a second writer for the same robot, and a disk that hangs at shutdown (issue [safe-storage])."""

from __future__ import annotations

import io
import logging
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Any, BinaryIO

import pytest

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.errors import LogLockedError, UsageError
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000
WORKTREE = Path(__file__).resolve().parents[2]


def _log(logger: AuditLogger, numbers: range) -> None:
    for i in numbers:
        p, b, a, e = synthetic_cycle(i)
        logger.log_cycle(i * PERIOD_NS, perception=p, belief=b, action=a, execution=e)


def _spawn(script: str, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(WORKTREE)}
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(script), *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


# --- 1. storage that disappears ------------------------------------------------------------


@pytest.mark.parametrize("threaded", [True, False], ids=["threaded", "synchronous"])
def test_a_deleted_root_is_recreated_and_the_loss_declared(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, threaded: bool
) -> None:
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=threaded))
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        _log(logger, range(20))
        assert logger.flush()
        copy = tmp_path / "before-loss.mcap"
        shutil.copy(logger.stats.segments[-1], copy)  # what was on disk, to find the last seal
        shutil.rmtree(root)  # the storage disappears under the running robot
        _log(logger, range(20, 40))
        assert logger.flush()
        # The lock went with the directory and was taken again: still one writer.
        with pytest.raises(LogLockedError):
            AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
        logger.close()

    cycles = {c.cycle: c for c in open_log(root).iter_cycles()}
    assert sorted(cycles) == list(range(20, 40))  # every cycle after the loss is on disk
    first = cycles[20].seal
    assert first is not None and first.dropped == 20  # the lost segment's cycles, declared
    # The chain goes on from the last seal written, into a new segment.
    last_before = open_log(copy).get_cycle(19)
    assert last_before is not None
    assert first.prev == digest(last_before.payloads["/trace/seal"])
    (segment,) = open_log(root).segments
    assert segment.session.segment == 1 and segment.session.prev_seal == first.prev
    stats = logger.stats
    assert stats.dropped_storage_lost == 20 and stats.written == 20 and stats.committed == 40
    assert stats.written + stats.dropped == stats.committed
    assert sum("storage" in r.message for r in caplog.records) == 1  # logged once


def test_a_deleted_single_file_log_goes_on_in_a_new_file(tmp_path: Path) -> None:
    path = tmp_path / "run" / "run.mcap"
    path.parent.mkdir()
    logger = AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=False))
    _log(logger, range(5))
    shutil.rmtree(path.parent)
    _log(logger, range(5, 10))
    logger.close()
    follow = path.with_name("run.000001.mcap")
    cycles = list(open_log(follow).iter_cycles())
    assert [c.cycle for c in cycles] == list(range(5, 10))
    assert cycles[0].seal is not None and cycles[0].seal.dropped == 5


def test_the_storage_check_costs_little_per_batch(tmp_path: Path) -> None:
    """One fstat per batch: far below a 10 Hz period, and below the batch's own write."""
    logger = AuditLogger(tmp_path / "root", robot_id="r", config=LoggerConfig(threaded=False))
    segment = logger._segment
    assert segment is not None
    n = 2000
    start = time.perf_counter_ns()
    for _ in range(n):
        assert not segment.storage_lost()
    per_check_us = (time.perf_counter_ns() - start) / n / 1000
    logger.close()
    assert per_check_us < 50  # typically ~1 us


# --- 2. one writer per robot and root ------------------------------------------------------

_HOLDER = """
    import sys, time
    from trace_runtime import AuditLogger, LoggerConfig
    from trace_runtime.testing import synthetic_cycle
    log = AuditLogger(sys.argv[1], robot_id="r", config=LoggerConfig(threaded=False))
    for i in range(5):
        p, b, a, e = synthetic_cycle(i)
        log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    print("ready", flush=True)
    time.sleep(60)
"""


def test_a_second_logger_for_the_same_robot_and_root_is_refused(tmp_path: Path) -> None:
    root = tmp_path / "root"
    first = AuditLogger(root, robot_id="r")
    with pytest.raises(LogLockedError, match=f"pid {os.getpid()}") as caught:
        AuditLogger(root, robot_id="r")
    assert caught.value.pid == os.getpid()
    _log(first, range(3))
    first.close()  # releases the lock
    second = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    _log(second, range(3, 5))
    second.close()
    assert [c.cycle for c in open_log(root).iter_cycles()] == list(range(5))


def test_a_second_logger_on_the_same_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    first = AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=False))
    with pytest.raises(LogLockedError):
        AuditLogger(path, robot_id="other", config=LoggerConfig(threaded=False))
    first.close()


def test_a_file_inside_a_root_takes_the_robots_root_lock(tmp_path: Path) -> None:
    """A second logger given a segment path inside the root (not the root) would fork the
    chain of the logger writing the root; it is refused like one given the root."""
    root = tmp_path / "root"
    first = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    with pytest.raises(LogLockedError):
        AuditLogger(root / "hot" / "r_000007.mcap", robot_id="r")
    first.close()


def test_two_robots_on_one_root_are_independent(tmp_path: Path) -> None:
    root = tmp_path / "root"
    a = AuditLogger(root, robot_id="a", config=LoggerConfig(threaded=False))
    b = AuditLogger(root, robot_id="b", config=LoggerConfig(threaded=False))
    _log(a, range(3))
    _log(b, range(4))
    a.close()
    b.close()
    robots = {s.session.robot_id for s in open_log(root).segments}
    assert robots == {"a", "b"}


def test_a_live_process_holds_the_lock_and_kill_9_releases_it(tmp_path: Path) -> None:
    root = tmp_path / "root"
    holder = _spawn(_HOLDER, str(root))
    try:
        assert holder.stdout is not None
        assert holder.stdout.readline().strip() == "ready", holder.stderr
        with pytest.raises(LogLockedError, match=f"pid {holder.pid}"):
            AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
        holder.send_signal(signal.SIGKILL)
        holder.wait(10)
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait(10)
        for stream in (holder.stdout, holder.stderr):
            if stream is not None:
                stream.close()
    # The kernel released the lock with the process: no stale lock, and the chain goes on.
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False))
    _log(logger, range(5, 8))
    logger.close()
    assert [c.cycle for c in open_log(root).iter_cycles()] == list(range(8))


# --- 3. bounded shutdown -------------------------------------------------------------------


class _HangingFile(io.FileIO):
    """A real file whose write() blocks on ``release`` while ``hang`` is set: a hung disk."""

    stuck = threading.Event()  # set once a write is blocked

    def __init__(self, path: Path, hang: threading.Event, release: threading.Event) -> None:
        super().__init__(path, "w+")
        self.hang, self.release = hang, release

    def write(self, data: Any) -> int:
        if self.hang.is_set():
            self.stuck.set()
            self.release.wait()
        return super().write(data)


def test_close_returns_within_its_timeout_when_the_disk_hangs(tmp_path: Path) -> None:
    hang, release = threading.Event(), threading.Event()

    def opener(path: Path) -> BinaryIO:
        return _HangingFile(path, hang, release)  # type: ignore[return-value]

    path = tmp_path / "hung.mcap"
    logger = AuditLogger(path, robot_id="r", config=LoggerConfig(opener=opener))
    _log(logger, range(3))
    assert logger.flush()
    hang.set()
    _HangingFile.stuck.clear()
    try:
        _log(logger, range(3, 4))
        assert _HangingFile.stuck.wait(5)  # the writer is inside cycle 3's write, for good
        _log(logger, range(4, 13))  # and these wait in the queue behind it
        start = time.monotonic()
        logger.close(timeout_s=1.0)
        elapsed = time.monotonic() - start
        assert elapsed < 2.0
        assert logger.stats.written == 3
        assert logger.stats.dropped_undelivered == 10
        assert logger._writer._thread is not None and logger._writer._thread.daemon
    finally:
        # The disk comes back: the writer finishes the batch it was in and ends the
        # segment, declaring the cycles it never wrote (schemas/PROFILE.md §7).
        hang.clear()
        release.set()
        assert logger._writer._thread is not None
        logger._writer._thread.join(5)
    assert not logger._writer._thread.is_alive()
    stats = logger.stats  # cycle 3 was written after all; 4..12 never will be
    assert (stats.written, stats.dropped_undelivered, stats.committed) == (4, 9, 13)
    assert [c.cycle for c in open_log(path).iter_cycles()] == [0, 1, 2, 3]
    closing = open_log(path).segments[0].metadata["trace.close"]
    assert closing == {"dropped_after_last_seal": "9", "last_sealed_cycle": "3"}


def test_a_synchronous_close_is_bounded_too(tmp_path: Path) -> None:
    hang, release = threading.Event(), threading.Event()

    def opener(path: Path) -> BinaryIO:
        return _HangingFile(path, hang, release)  # type: ignore[return-value]

    config = LoggerConfig(threaded=False, batch_cycles=4, opener=opener)
    logger = AuditLogger(tmp_path / "hung.mcap", robot_id="r", config=config)
    _log(logger, range(3))  # held for a batch of 4: close() must write them
    hang.set()
    try:
        start = time.monotonic()
        logger.close(timeout_s=0.5)
        assert time.monotonic() - start < 1.5
        assert logger.stats.dropped_undelivered == 3 and logger.stats.written == 0
    finally:
        hang.clear()
        release.set()
    deadline = time.monotonic() + 5
    while logger.stats.dropped_undelivered and time.monotonic() < deadline:
        time.sleep(0.01)  # the disk is back: the closer thread writes them after all
    assert logger.stats.written == 3 and logger.stats.dropped_undelivered == 0


_HUNG_AT_EXIT = """
    import sys, threading, time, io
    from trace_runtime import AuditLogger, LoggerConfig
    from trace_runtime.testing import synthetic_cycle
    hang = threading.Event()
    class Hung(io.FileIO):
        def write(self, data):
            if hang.is_set():
                threading.Event().wait()  # forever
            return super().write(data)
    log = AuditLogger(sys.argv[1], robot_id="r", config=LoggerConfig(opener=lambda p: Hung(p, "w")))
    hang.set()
    for i in range(5):
        p, b, a, e = synthetic_cycle(i)
        log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    start = time.monotonic()
    log.close(timeout_s=0.5)
    print(f"{time.monotonic() - start:.3f} {log.stats.dropped_undelivered}", flush=True)
"""


def test_a_robot_with_a_hung_disk_still_exits(tmp_path: Path) -> None:
    proc = _spawn(_HUNG_AT_EXIT, str(tmp_path / "hung.mcap"))
    try:
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    elapsed, undelivered = out.split()
    assert float(elapsed) < 1.5 and int(undelivered) == 5
    assert "5 cycle(s)" in err  # logged once: the count that close could not write


@pytest.mark.parametrize("period_s", [0.0, -1.0, 1e-10, float("nan")])
def test_a_period_no_reader_accepts_is_refused_at_construction(
    tmp_path: Path, period_s: float
) -> None:
    """Readers refuse a period under 1 us (PROFILE section 2): the logger must not write one."""
    with pytest.raises(UsageError, match="period_s must be at least"):
        AuditLogger(tmp_path / "run.mcap", robot_id="r", period_s=period_s)
