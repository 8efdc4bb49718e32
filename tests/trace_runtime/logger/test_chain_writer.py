"""A log's storage lost or full under a running robot (``trace_runtime.logger.chain_writer``): a
deleted root is recreated and a deleted file replaced, the loss declared in the next seal, for
one fstat per batch; after a full disk the file's real end decides which cycles were written,
so the chain goes on from what the file holds and ``verify`` finds nothing."""

from __future__ import annotations

import logging
import random
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.trace_runtime.full_disk import (
    FullDisk,
    assert_log_agrees,
    fill_tmpfs,
    robot_cycle,
    run_logger,
    tiny_tmpfs,
)
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


# --- a full disk -------------------------------------------------------------------------


def _run_on(disk: FullDisk, root: Path, *, batch_cycles: int, cycles: int) -> None:
    config = LoggerConfig(
        threaded=False, batch_cycles=batch_cycles, checkpoint_interval_s=2.0, opener=disk.open
    )
    logger = AuditLogger(root, robot_id="r", config=config)
    run_logger(logger, cycles, robot_cycle)
    assert_log_agrees(root, logger.stats)


_LANDS: dict[str, Callable[[random.Random], Callable[[int], int]]] = {
    "whole batch landed": lambda rng: lambda n: n,
    "part landed": lambda rng: lambda n: rng.randrange(1, n) if n > 1 else 0,
    "half landed": lambda rng: lambda n: n // 2,
    "nothing landed": lambda rng: lambda n: 0,
}


@pytest.mark.parametrize("rollback_works", [False, True], ids=["rollback fails", "rolled back"])
@pytest.mark.parametrize("variant", list(_LANDS))
def test_after_a_full_disk_the_file_decides_what_was_written(
    tmp_path: Path, variant: str, rollback_works: bool
) -> None:
    """ENOSPC at a random write (a batch, a segment's header, a checkpoint, the summary),
    with some of its bytes in the file and the rollback failing or not, the disk full for a
    while after: the log verifies, and the cycles in the file are counted as written."""
    cycles = 80
    for seed in range(30 if not rollback_works else 8):
        rng = random.Random(seed)
        batch_cycles = rng.randrange(1, 5)
        disk = FullDisk(
            # After the first segment's header (2 writes), up to the last segment's summary.
            fails_at=rng.randrange(3, cycles // batch_cycles + 8),
            lands=_LANDS[variant](rng),
            stays_full=rng.choice([0, 0, 1, 3, 20, 1000]),
            rollback_works=rollback_works,
        )
        _run_on(disk, tmp_path / f"{seed}", batch_cycles=batch_cycles, cycles=cycles)


def _landing(fraction: float) -> Callable[[int], int]:
    return lambda n: round(n * fraction)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    disk=st.builds(
        FullDisk,
        fails_at=st.integers(3, 70),
        lands=st.floats(0, 1).map(_landing),
        stays_full=st.integers(0, 30),
        rollback_works=st.booleans(),
    ),
    batch_cycles=st.integers(1, 6),
)
def test_any_full_disk_leaves_a_log_that_verifies(
    tmp_path_factory: pytest.TempPathFactory, disk: FullDisk, batch_cycles: int
) -> None:
    _run_on(disk, tmp_path_factory.mktemp("root"), batch_cycles=batch_cycles, cycles=60)


def test_a_batch_that_reached_the_file_is_chained_from_not_dropped(tmp_path: Path) -> None:
    """The whole batch is in the file when the write raises and the rollback fails: the next
    segment continues from that batch's last seal and declares nothing."""
    disk = FullDisk(fails_at=0, lands=lambda n: n)
    root = tmp_path / "root"
    logger = AuditLogger(root, robot_id="r", config=LoggerConfig(threaded=False, opener=disk.open))
    log_cycles(logger, range(5))
    disk.fails_at = disk.writes + 1  # cycle 5's batch
    log_cycles(logger, range(5, 10))
    logger.close()
    assert logger.stats.dropped_io == 0 and logger.stats.written == 10
    log = open_log(root)
    assert [s.session.segment for s in log.segments] == [0, 1]
    cycles = {c.cycle: c for c in log.iter_cycles()}
    assert sorted(cycles) == list(range(10))
    sixth = cycles[6].seal
    assert sixth is not None and sixth.dropped == 0
    assert sixth.prev == digest(cycles[5].payloads["/trace/seal"])
    assert log.segments[1].session.prev_seal == sixth.prev
    assert_log_agrees(root, logger.stats)


@pytest.mark.parametrize("rollback_works", [False, True], ids=["rollback fails", "rolled back"])
def test_a_closing_checkpoint_the_disk_refuses_leaves_the_segment_unfinished(
    tmp_path: Path, rollback_works: bool
) -> None:
    """A finished segment without its closing checkpoint reads as cut short: when the disk
    refuses that checkpoint, the segment is left without a summary, as a crash leaves it."""
    # Writes: the header and session metadata, one per cycle, then the closing checkpoint.
    disk = FullDisk(fails_at=2 + 10 + 1, lands=lambda n: 0, rollback_works=rollback_works)
    root = tmp_path / "root"
    config = LoggerConfig(threaded=False, checkpoint_interval_s=None, opener=disk.open)
    logger = AuditLogger(root, robot_id="r", config=config)
    log_cycles(logger, range(10))
    logger.close()
    assert logger.stats.checkpoint_failures == 1 and logger.stats.written == 10
    (segment,) = open_log(root).segments
    assert segment.info.recovered
    assert_log_agrees(root, logger.stats)


def test_a_robot_filling_a_real_tmpfs_leaves_a_log_that_verifies(tmp_path: Path) -> None:
    """A robot logs into a 2 MiB tmpfs that some ballast fills; in some runs the ballast is
    deleted after the first drop and the robot goes on. Every run verifies, and the cycles
    in the files are the cycles counted as written."""
    with tiny_tmpfs(tmp_path / "disk") as disk:
        for run in range(12):
            root = disk / f"root{run}"
            stats = fill_tmpfs(disk, root, random.Random(run))
            assert stats.dropped_io > 0, "the disk never filled"
            assert_log_agrees(root, stats)
            shutil.rmtree(root)
