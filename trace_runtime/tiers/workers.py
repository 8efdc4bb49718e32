"""Compaction fanned out to worker processes: each writes and checks whole segments, read
from disk by the worker itself; the parent swaps the copies in, one at a time, in plan order."""

from __future__ import annotations

import os
import pickle
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from trace_runtime.errors import LogReadError
from trace_runtime.reading.reader import Segment
from trace_runtime.tier_formats.warm import WarmPolicy
from trace_runtime.tiers._files import PartialOpener
from trace_runtime.tiers.plan import segment_result
from trace_runtime.tiers.replace import failed, swap_in
from trace_runtime.tiers.report import ColdOptions, SegmentResult
from trace_runtime.tiers.write import write_replacement

WorkerSettings = tuple[WarmPolicy, ColdOptions, PartialOpener]
"""What a worker is sent besides paths: the warm policy, the cold options, the opener."""


def _write_in_worker(
    root: Path, path: Path, tier: str, settings: WorkerSettings
) -> int | str | None:
    """In a worker process: ``write_replacement`` of one segment, which the worker opens and
    reads from disk itself (nothing but paths and options crosses the process boundary).
    Returns the warm tier's full cycle count (None for cold), or the failure detail (str)."""
    warm_policy, cold_options, opener = settings
    try:
        segment = Segment(path)
    except LogReadError as err:
        return str(err)
    written = write_replacement(
        root,
        path,
        segment,
        tier,
        warm_policy=warm_policy,
        cold_options=cold_options,
        advance=lambda _n: None,
        opener=opener,
    )
    return written if isinstance(written, str) else written.full_cycles


def compact_in_workers(
    root: Path,
    plan: list[tuple[Path, Segment]],
    tier: str,
    settings: WorkerSettings,
    advance: Callable[[int, str], None],
) -> Iterator[tuple[Path, SegmentResult]]:
    """Compact the planned segments in ``cold.jobs`` worker processes (``settings``: the
    warm policy, cold options and opener), one segment per task. Each worker writes and
    checks its segment's partial file; this process then swaps the replacements in, one at a
    time and in plan order, exactly as ``compact_segment`` does (rename, fsync, catalog,
    remove the source)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # spawn: a worker never inherits the threads or locks of an embedding process
    pool = ProcessPoolExecutor(
        min(settings[1].jobs, len(plan)),
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_exit_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        jobs = [
            (
                path,
                segment,
                time.perf_counter(),
                pool.submit(_write_in_worker, root, path, tier, settings),
            )
            for path, segment in plan
        ]
        for path, segment, started, job in jobs:
            target = root / tier / path.name
            result = segment_result(root, path, segment, target, status="compacted", detail="")
            outcome = job.result()
            if isinstance(outcome, str):
                yield path, failed(result, outcome, started)
                continue
            yield (
                path,
                swap_in(root, path, tier, result, full_cycles=outcome, started=started),
            )
            advance(result.cycles, path.name)
    finally:
        pool.shutdown(cancel_futures=True)


def picklable(value: Any) -> bool:
    """Whether ``value`` can be sent to a worker process (a test's opener may not be)."""
    try:
        pickle.dumps(value)
    except (pickle.PicklingError, TypeError, AttributeError):
        return False
    return True


def _exit_with_parent(parent: int) -> None:
    """In a worker: exit when the compacting process is gone (killed with -9, it cannot
    shut its pool down, and an idle worker would wait for work forever). A worker writes a
    partial file, so it stops soon: the next run may start (the lock died with the parent),
    and a worker still busy then could at worst remove the partial of the same name and make
    that run fail the segment (a worker never renames a file and never touches a source)."""
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.1)
        os._exit(1)

    threading.Thread(target=watch, name="trace-compact-parent-watch", daemon=True).start()
