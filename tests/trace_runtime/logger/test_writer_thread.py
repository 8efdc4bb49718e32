"""A disk that hangs at shutdown (``trace_runtime.logger.writer_thread``): ``close()`` returns
within its timeout, threaded or not, the cycles it could not write are counted, and a robot with a
hung disk still exits."""

from __future__ import annotations

import io
import threading
import time
from pathlib import Path
from typing import Any, BinaryIO

from tests.trace_runtime.robot_helpers import log_cycles, spawn
from trace_runtime import AuditLogger, LoggerConfig, open_log


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
    log_cycles(logger, range(3))
    assert logger.flush()
    hang.set()
    _HangingFile.stuck.clear()
    try:
        log_cycles(logger, range(3, 4))
        assert _HangingFile.stuck.wait(5)  # the writer is inside cycle 3's write, for good
        log_cycles(logger, range(4, 13))  # and these wait in the queue behind it
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
    log_cycles(logger, range(3))  # held for a batch of 4: close() must write them
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
    proc = spawn(_HUNG_AT_EXIT, str(tmp_path / "hung.mcap"))
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
