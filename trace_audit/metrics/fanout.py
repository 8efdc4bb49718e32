"""The entry point: plan a log's segments, score them here or fanned out, report.

One process scores each robot's segments in one pass; with ``workers`` (or an
``executor``, e.g. a Dask cluster's) each segment is one task that first reads the tail of
the robot's previous segment, and the partial results are merged in plan order, so the
report is the same however the work was spread.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path

from trace_audit.evidence import recordings_for
from trace_audit.log_time import LogClock
from trace_audit.metrics.config import MetricsConfig
from trace_audit.metrics.report import build_report
from trace_audit.metrics.results import MetricsReport
from trace_audit.metrics.scan import score_robot, score_segment
from trace_audit.metrics.sums import ScanResult
from trace_audit.selection import Selection, each_robot
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.reading.logset import Log, open_logs
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_SEAL

__all__ = ["ProgressCallback", "compute_metrics"]

ProgressCallback = Callable[[int, int | None], None]
"""Called with (cycles done, cycles expected or None) as the scan advances."""


@dataclass(frozen=True, slots=True)
class _Task:
    path: str
    previous: str | None
    config: MetricsConfig
    recordings: Recordings | None
    """The log's one resolution of evidence (sent to a worker as its file list)."""


def _plan(log: Log) -> list[tuple[str, list[Segment]]]:
    """Each robot's segments in chain order, robots in order of their first record."""
    plan = [(robot, log.segments_of(robot)) for robot in log.robots]
    plan.sort(key=lambda item: min(s.info.start_ns for s in item[1]))
    return plan


def _run_task(task: _Task) -> ScanResult:
    return score_segment(task.path, task.previous, task.config, recordings=task.recordings)


def _usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask, e.g. a container's share)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0)) or 1
    return os.cpu_count() or 1


def _expected_cycles(segment: Segment) -> int:
    return segment.info.channels.get(TOPIC_SEAL, 0)


def _tasks(
    plan: list[tuple[str, list[Segment]]],
    cfg: MetricsConfig,
    recordings: Recordings | None,
    *,
    absolute: bool,
) -> list[_Task]:
    """One task per segment of the plan, naming the robot's segment before it (if any).

    A cluster's worker resolves a relative path in its own directory: with ``absolute`` the
    files are named by absolute path (the report still names them as given)."""

    def where(path: Path) -> str:
        return str(path.absolute()) if absolute else str(path)

    return [
        _Task(where(seg.path), where(segs[i - 1].path) if i else None, cfg, recordings)
        for _robot, segs in plan
        for i, seg in enumerate(segs)
    ]


def _check_window(log: Log, cfg: MetricsConfig) -> None:
    """A window that misses every robot's log is a usage error (as a time outside the log
    is to ``explain``), not a report of 0 decisions."""
    if cfg.start_ns is None and cfg.end_ns is None:
        return
    lo = cfg.start_ns if cfg.start_ns is not None else -(1 << 63)
    hi = cfg.end_ns if cfg.end_ns is not None else 1 << 63
    robots = each_robot(log)
    if any(r.start_ns <= hi and r.end_ns >= lo for r in robots):
        return
    clock = LogClock.of(log)
    ends = (("from", cfg.start_ns), ("to", cfg.end_ns))
    window = " ".join(f"{word} {clock.show(t)}" for word, t in ends if t is not None)
    ranges = "; ".join(
        f"{r.first_robot} {LogClock.of(r).show(r.start_ns)} .. {LogClock.of(r).show(r.end_ns)}"
        for r in robots
    )
    raise UsageError(f"the window ({window}) holds no decision of the log: {ranges}")


def compute_metrics(
    paths: Sequence[str | Path],
    config: MetricsConfig | None = None,
    *,
    robots: Sequence[str] | None = None,
    progress: ProgressCallback | None = None,
    executor: Executor | None = None,
    recordings: Recordings | None = None,
) -> MetricsReport:
    """Score every decision in the given logs (files, directories or log roots) in one pass.

    ``robots`` selects robots (``trace_audit.selection``; a robot not in the logs is a
    ``UsageError`` naming those that are). When more than one robot is read and
    ``config.by`` is None, the decisions are grouped by robot: a question over time is
    answered per robot. Memory is bounded: cycles are streamed, sums accumulated, and at
    most ``config.max_listed`` failing decisions and gaps kept for listing. Given an
    ``executor`` (e.g. a Dask cluster's, ``trace_audit.fleet.cluster``), segments are
    scored there, one task each, instead of in local processes; the report is the same.
    Evidence in external recordings resolves against ``recordings`` when given (a caller's
    one resolution, e.g. the incident report's), else against those the log declares and
    ``config.evidence`` (``evidence.recordings_for``).
    """
    cfg = config or MetricsConfig()
    started = time.perf_counter()
    selection = Selection(robots=tuple(robots or ()))
    log = selection.of(open_logs(paths))
    _check_window(log, cfg)
    if cfg.by is None and len(log.robots) > 1:
        cfg = replace(cfg, by="robot")
    plan = _plan(log)
    if recordings is None:
        recordings = recordings_for(log, cfg.evidence)
    expected = sum(_expected_cycles(s) for _, segs in plan for s in segs) or None
    total = ScanResult()
    done = 0

    def advance(n: int) -> None:
        nonlocal done
        done += n
        if progress is not None:
            progress(done, expected)

    _score_plan(plan, cfg, recordings, executor, total=total, advance=advance)
    elapsed = time.perf_counter() - started
    segments_read = tuple(str(s.path) for _, segs in plan for s in segs)
    report = build_report(
        paths,
        cfg,
        log=log,
        total=total,
        segments=segments_read,
        elapsed=elapsed,
        by=cfg.by,
        robots=selection.robots,
    )
    if report.overall.decisions == 0 and cfg.start_ns is None and cfg.end_ns is None:
        # As info, explain and verify say it: nothing to score is an empty log, not 0 %.
        raise LogReadError(str(paths[0]), "the log holds no decision cycles")
    return report


def _score_plan(
    plan: list[tuple[str, list[Segment]]],
    cfg: MetricsConfig,
    recordings: Recordings | None,
    executor: Executor | None,
    *,
    total: ScanResult,
    advance: Callable[[int], None],
) -> None:
    """Score the plan into ``total``: on ``executor`` when given, else in this process (one
    pass a robot) or, with ``cfg.workers``, in local processes."""
    tasks = _tasks(plan, cfg, recordings, absolute=executor is not None)
    workers = min(cfg.workers, len(tasks), _usable_cpus())
    if executor is not None:
        _fan_out(executor, tasks, plan=plan, total=total, advance=advance, limit=cfg.max_listed)
    elif workers <= 1:
        for _robot, segments in plan:
            total.merge(score_robot(segments, cfg, advance, recordings), cfg.max_listed)
    else:
        # Each task scores one segment; it first reads the tail of the robot's previous
        # segment, so chain links, gaps and refs across the boundary come out as in one pass.
        # The longest segments start first (a short one left for last keeps both workers
        # busy to the end); the partials are merged in plan order whatever order they finish
        # in, so the sums and the listed failures are the same in every run.
        # Imported here: the process pool's modules (multiprocessing, pickle: ~5 ms) are
        # start-up that a one-process run, the default, would pay for nothing.
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=workers) as pool:
            _fan_out(pool, tasks, plan=plan, total=total, advance=advance, limit=cfg.max_listed)


def _fan_out(
    executor: Executor,
    tasks: list[_Task],
    *,
    plan: list[tuple[str, list[Segment]]],
    total: ScanResult,
    advance: Callable[[int], None],
    limit: int,
) -> None:
    """Score each task on ``executor``; merge the partials in plan order."""
    sizes = [s.info.bytes for _robot, segs in plan for s in segs]
    order = sorted(range(len(tasks)), key=lambda i: -sizes[i])
    futures = {i: executor.submit(_run_task, tasks[i]) for i in order}
    for future in as_completed(futures.values()):
        advance(future.result().cycles)
    for i in range(len(tasks)):
        total.merge(futures[i].result(), limit)
