"""I/O failure never reaches the control loop: cycles are dropped, counted and sealed."""

from __future__ import annotations

import errno
import io
import logging
import shutil
import threading
from pathlib import Path
from typing import Any, BinaryIO

import pytest

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.testing import synthetic_cycle


class FlakyFile(io.FileIO):
    """A real file whose writes fail with ``error`` while ``failing`` is set."""

    def __init__(self, path: Path, state: dict[str, Any]) -> None:
        super().__init__(path, "w+")
        self.state = state

    def write(self, data: Any) -> int:
        if self.state["failing"]:
            # A partial write first, as a filling disk does, then the error.
            super().write(bytes(data)[: len(data) // 3])
            raise OSError(self.state.get("errno", errno.ENOSPC), "No space left on device")
        return super().write(data)


def _opener(state: dict[str, Any]) -> Any:
    def open_flaky(path: Path) -> BinaryIO:
        return FlakyFile(path, state)  # type: ignore[return-value]

    return open_flaky


def _log_cycles(
    logger: AuditLogger, numbers: range, failing: set[int], state: dict[str, Any]
) -> None:
    for i in numbers:
        state["failing"] = i in failing
        p, b, a, e = synthetic_cycle(i)
        logger.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)


def test_disk_full_drops_cycles_and_the_next_seal_counts_them(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    state: dict[str, Any] = {"failing": False}
    path = tmp_path / "full.mcap"
    logger = AuditLogger(
        path, robot_id="r", config=LoggerConfig(threaded=False, opener=_opener(state))
    )
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        _log_cycles(logger, range(20), failing={5, 6, 7, 12}, state=state)
    state["failing"] = False
    logger.close()
    assert logger.stats.dropped_io == 4 and logger.stats.written == 16
    assert sum("audit write failed" in r.message for r in caplog.records) == 1  # once, not 4x
    cycles = {c.cycle: c for c in open_log(path).iter_cycles()}
    assert sorted(cycles) == [n for n in range(20) if n not in {5, 6, 7, 12}]
    assert cycles[8].seal is not None and cycles[8].seal.dropped == 3
    assert cycles[13].seal is not None and cycles[13].seal.dropped == 1
    # The chain skips the dropped cycles: cycle 8 links straight to cycle 4's seal.
    assert cycles[8].seal.prev == digest(cycles[4].payloads["/trace/seal"])


def test_a_failure_the_file_cannot_roll_back_moves_to_a_new_segment(tmp_path: Path) -> None:
    state: dict[str, Any] = {"failing": False}

    class Unrecoverable(FlakyFile):
        def truncate(self, size: Any = None) -> int:
            if self.state["failing"]:
                raise OSError(errno.EIO, "I/O error")
            return super().truncate(size)

    def opener(path: Path) -> BinaryIO:
        return Unrecoverable(path, state)  # type: ignore[return-value]

    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False, opener=opener))
    _log_cycles(logger, range(10), failing={4}, state=state)
    state["failing"] = False
    logger.close()
    log = open_log(root)
    assert len(log.segments) == 2
    assert log.segments[0].info.recovered  # abandoned mid-write: no summary, read by scan
    numbers = [c.cycle for c in log.iter_cycles()]
    assert numbers == [0, 1, 2, 3, 5, 6, 7, 8, 9]
    assert log.get_cycle(5) is not None and log.get_cycle(5).seal.dropped == 1  # type: ignore[union-attr]


def test_a_full_queue_drops_instead_of_blocking_the_control_loop(tmp_path: Path) -> None:
    gate = threading.Event()
    gate.set()  # let the header and session metadata through
    stuck = threading.Event()  # the writer is inside a write, waiting at the gate

    class SlowFile(io.FileIO):
        def write(self, data: Any) -> int:
            if not gate.is_set():
                stuck.set()
            gate.wait(5)
            return super().write(data)

    path = tmp_path / "slow.mcap"
    logger = AuditLogger(
        path, robot_id="r", config=LoggerConfig(queue_cycles=4, opener=lambda p: SlowFile(p, "w"))
    )  # type: ignore[arg-type,return-value]
    gate.clear()
    for i in range(50):
        p, b, a, e = synthetic_cycle(i)
        logger.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
        if i == 0:
            # Wait until the writer holds cycle 0 at the gate, so the queue fills behind it
            # however the threads are scheduled (and the last cycles are always dropped).
            assert stuck.wait(5)
    gate.set()
    logger.close()
    assert logger.stats.dropped_queue_full > 0
    cycles = list(open_log(path).iter_cycles())
    declared = sum(c.seal.dropped for c in cycles if c.seal is not None)
    assert len(cycles) + logger.stats.dropped_queue_full == 50
    # Every gap before the last written cycle is declared by a seal ...
    assert declared + len(cycles) == cycles[-1].cycle + 1
    # ... and the drops after it, which no seal follows, by the segment's closing record.
    closing = open_log(path).segments[0].metadata["trace.close"]
    assert closing == {
        "dropped_after_last_seal": str(49 - cycles[-1].cycle),
        "last_sealed_cycle": str(cycles[-1].cycle),
    }


def test_a_lost_directory_never_raises_into_the_loop(tmp_path: Path) -> None:
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False, max_segment_s=0.5))
    _log_cycles(logger, range(3), failing=set(), state={"failing": False})
    shutil.rmtree(root)  # the storage disappears under the robot
    root.touch()  # and a file now sits where the directory was: every open fails
    _log_cycles(logger, range(3, 30), failing=set(), state={"failing": False})
    logger.close()
    assert logger.stats.committed == 30
    assert logger.stats.dropped_io > 0


def test_an_exception_in_the_robot_aborts_the_cycle_and_is_declared(tmp_path: Path) -> None:
    path = tmp_path / "abort.mcap"
    with AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=False)) as logger:
        logger.log_cycle(0, action=synthetic_cycle(0)[2])
        with pytest.raises(ZeroDivisionError), logger.cycle(100_000_000):
            _ = 1 / 0
        logger.log_cycle(200_000_000, action=synthetic_cycle(2)[2])
    cycles = list(open_log(path).iter_cycles())
    assert [c.cycle for c in cycles] == [0, 2]
    assert cycles[1].seal is not None and cycles[1].seal.dropped == 1


def test_a_segment_that_fails_while_opening_does_not_leak_its_file(tmp_path: Path) -> None:
    state: dict[str, Any] = {"failing": False}
    opened: list[io.FileIO] = []

    class Unrecoverable(FlakyFile):
        def truncate(self, size: Any = None) -> int:
            if self.state["failing"]:
                raise OSError(errno.EIO, "I/O error")
            return super().truncate(size)

    def opener(path: Path) -> BinaryIO:
        stream = Unrecoverable(path, state)
        opened.append(stream)
        return stream  # type: ignore[return-value]

    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False, opener=opener))
    # Cycle 2 breaks the segment; cycles 3-5 each try a new one, whose header cannot be
    # written either. Every file given up on must be closed, not left to the collector.
    _log_cycles(logger, range(8), failing={2, 3, 4, 5}, state=state)
    assert all(stream.closed for stream in opened[:-1])
    logger.close()
    assert all(stream.closed for stream in opened)
    assert [c.cycle for c in open_log(root).iter_cycles()] == [0, 1, 6, 7]
