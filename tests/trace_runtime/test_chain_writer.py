"""A log's storage lost under a running robot: a deleted root is recreated and a deleted
file replaced, the loss declared in the next seal, for one fstat per batch
(``trace_runtime.chain_writer``)."""

from __future__ import annotations

import logging
import shutil
import time
from pathlib import Path

import pytest

from tests.trace_runtime.robot_helpers import log_cycles
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.errors import LogLockedError


@pytest.mark.parametrize("threaded", [True, False], ids=["threaded", "synchronous"])
def test_a_deleted_root_is_recreated_and_the_loss_declared(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, threaded: bool
) -> None:
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=threaded))
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        log_cycles(logger, range(20))
        assert logger.flush()
        copy = tmp_path / "before-loss.mcap"
        shutil.copy(logger.stats.segments[-1], copy)  # what was on disk, to find the last seal
        shutil.rmtree(root)  # the storage disappears under the running robot
        log_cycles(logger, range(20, 40))
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
    log_cycles(logger, range(5))
    shutil.rmtree(path.parent)
    log_cycles(logger, range(5, 10))
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
