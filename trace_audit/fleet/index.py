"""Build and incrementally update the fleet index: Parquet tables of every decision.

The index is a directory::

    INDEX/index.json                                      manifest: version, config, segments
    INDEX/decisions/robot=R/day=YYYY-MM-DD/<seg>.parquet   one file per segment and day
    INDEX/entities/...  INDEX/channels/...  INDEX/checks/...  INDEX/gaps/...  INDEX/segments/...

``day`` is the UTC day on a wall clock and ``run-<first segment>`` on a sim or monotonic
clock (``rows.partition_of``): the runs are the robots' clock runs among this run's inputs
(``Log.clock_runs``).

A segment's rows depend on its bytes and, through the chain link, the sensor window and
the gap rule at its start, on the bytes of the robot's previous segment. The manifest
keeps both digests (the log root's catalog's SHA-256, or the file's when it is not in a
root) for each chain position (robot, segment number, first cycle); a run re-indexes only
positions whose digests changed: new segments, a segment compacted into another tier, and
the one after it. Positions not among the inputs are kept (index one new file at a time).
Each segment is one task (``fleet.task``, on a local process or a Dask worker) scored by
``trace_audit.metrics.score_segment``, which writes its own files; the manifest is replaced
last. Which file holds each position when the inputs hold it twice is ``fleet.copies``'.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from trace_audit.fleet.copies import (
    against_manifest,
    chain_position,
    one_copy_each,
    open_refusing_forks,
)
from trace_audit.fleet.folder import (
    MANIFEST,
    check_target,
    discard_unlisted,
    index_lock,
    load_manifest,
    remove_own,
    write_manifest,
)
from trace_audit.fleet.rows import partition_of
from trace_audit.fleet.tables import INDEX_VERSION
from trace_audit.fleet.task import IndexedSegment, IndexTask, index_segment
from trace_audit.metrics import MetricsConfig
from trace_runtime.errors import StorageError
from trace_runtime.reading.logset import Log
from trace_runtime.tiers.catalog import file_digest

__all__ = ["MANIFEST", "IndexReport", "build_index", "load_manifest"]

ProgressCallback = Callable[[int, int | None], None]


@dataclass(frozen=True, slots=True)
class IndexReport:
    """What ``build_index`` did."""

    index: str
    version: int
    segments: int
    indexed: tuple[str, ...]
    """Segment files (re)indexed in this run."""
    unchanged: int
    decisions_written: int
    decisions_total: int
    unreadable: tuple[str, ...]
    elapsed_s: float
    cycles_per_s: float
    files: int = 0
    bytes: int = 0
    notes: tuple[str, ...] = field(default_factory=tuple)


def _files_intact(out: Path, entry: dict[str, Any]) -> bool:
    """Whether every file the manifest lists for a position is there and has a readable
    Parquet footer (a deleted or half-written file is indexed again)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    for rel in entry.get("files") or ():
        try:
            pq.read_metadata(out / rel)
        except (OSError, pa.ArrowException):  # missing, truncated or not Parquet: re-index
            return False
    return True


def _digests(log: Log, cache: dict[str, Any]) -> dict[Path, str]:
    """SHA-256 of every segment file: from the manifest's (size, mtime) cache, else read.
    Never from a log root's catalog: it is a hint anyone who sent the root could forge."""
    out: dict[Path, str] = {}
    for segment in log.segments:
        path = segment.path
        stat = path.stat()
        cached = cache.get(str(path.resolve()))
        if cached and cached[0] == stat.st_size and cached[1] == stat.st_mtime_ns:
            out[path] = cached[2]
        else:
            out[path] = file_digest(path)
        cache[str(path.resolve())] = [stat.st_size, stat.st_mtime_ns, out[path]]
    return out


def _plan(
    log: Log,
    digests: dict[Path, str],
    out: Path,
    config: MetricsConfig,
    left_out: set[Path] = frozenset(),  # type: ignore[assignment]
) -> list[IndexTask]:
    tasks: list[IndexTask] = []
    runs = _runs(log)
    for robot in log.robots:
        segments = [s for s in log.segments_of(robot) if s.path not in left_out]
        for i, segment in enumerate(segments):
            previous = segments[i - 1] if i else None
            tasks.append(
                IndexTask(
                    key=chain_position(segment),
                    path=str(segment.path.resolve()),
                    previous=str(previous.path.resolve()) if previous else None,
                    sha256=digests[segment.path],
                    previous_sha256=digests[previous.path] if previous else None,
                    out=str(out),
                    gap_tolerance=config.gap_tolerance,
                    sensor_window=config.sensor_window,
                    run=runs[segment.path],
                )
            )
    return tasks


def _runs(log: Log) -> dict[Path, str | None]:
    """Each segment's run partition (``partition_of``): the clock run of its robot it
    belongs to (``Log.clock_runs``), named by the run's first segment in chain order."""
    out: dict[Path, str | None] = {}
    for run in log.clock_runs():
        for robot in run.robots:
            chain = run.segments_of(robot)
            partition = partition_of(run.clock, run.start_ns, chain[0].session.segment)
            out.update((s.path, partition) for s in chain)
    return out


def _select(
    tasks: list[IndexTask], known: dict[str, Any], target: Path, notes: list[str]
) -> tuple[list[IndexTask], list[IndexTask]]:
    """The tasks the index keeps (a copy of a position it already holds from a better file
    is dropped, with a note) and, of those, the ones to (re)index."""
    kept: list[IndexTask] = []
    for task in tasks:
        note = against_manifest(task, known.get(task.key))
        if note is None:
            kept.append(task)
        else:
            notes.append(note)
    todo = [
        t
        for t in kept
        if not (_unchanged(known.get(t.key), t) and _files_intact(target, known[t.key]))
    ]
    return kept, todo


def build_index(
    paths: Sequence[str | Path],
    out: str | Path,
    *,
    config: MetricsConfig | None = None,
    workers: int = 1,
    executor: Executor | None = None,
    progress: ProgressCallback | None = None,
) -> IndexReport:
    """Index every decision of the given logs into ``out``; only new or changed segments
    are read. Segments run on ``executor`` (a Dask cluster's) when given, else on up to
    ``workers`` local processes."""
    started = time.perf_counter()
    cfg = config or MetricsConfig()
    # Absolute on the client: a Dask worker runs in its own directory, where a relative
    # --out would name another place (the files landed there, the manifest here).
    target = Path(out).absolute()
    new = not target.exists()
    check_target(target)  # a folder that is not ours is refused before the lock is made in it
    try:
        with index_lock(target):
            try:
                return _build(
                    paths,
                    target,
                    out=str(out),
                    cfg=cfg,
                    workers=workers,
                    executor=executor,
                    progress=progress,
                    started=started,
                )
            except StorageError:
                discard_unlisted(target)  # the files of a run that could not finish
                raise
    except StorageError:
        if new:
            with contextlib.suppress(OSError):
                target.rmdir()  # made by this run; only if nothing (another run's lock) is in it
        raise


def _build(
    paths: Sequence[str | Path],
    target: Path,
    *,
    out: str,
    cfg: MetricsConfig,
    workers: int,
    executor: Executor | None,
    progress: ProgressCallback | None,
    started: float,
) -> IndexReport:
    """``build_index`` with the folder's lock held."""
    manifest = check_target(target) or {"segments": {}}
    settings = {"gap_tolerance": cfg.gap_tolerance, "sensor_window": cfg.sensor_window}
    known: dict[str, Any] = dict(manifest.get("segments", {}))
    if manifest.get("config") not in (None, settings):
        known = {}  # scored under other settings: every row is rebuilt
    log = open_refusing_forks(paths)
    cache: dict[str, Any] = dict(manifest.get("digests", {}))
    left_out, notes = one_copy_each(log)
    tasks = _plan(log, _digests(log, cache), target, cfg, left_out)
    tasks, todo = _select(tasks, known, target, notes)
    opened = {str(s.path.resolve()): s for s in log.segments}
    expected = sum(opened[t.path].info.channels.get("/trace/seal", 0) for t in todo)
    target.mkdir(parents=True, exist_ok=True)
    done = _index_segments(todo, executor, workers, progress, expected)
    cycles = sum(result.decisions for result in done)
    _record(target, manifest, known, done, settings=settings, digests=cache)
    elapsed = time.perf_counter() - started
    files = [target / rel for entry in known.values() for rel in entry["files"]]
    return IndexReport(
        index=str(out),
        version=INDEX_VERSION,
        segments=len(known),
        indexed=tuple(r.path for r in done),
        unchanged=len(tasks) - len(todo),
        decisions_written=cycles,
        decisions_total=sum(int(e["decisions"]) for e in known.values()),
        unreadable=tuple(f"{p.path}: {p.reason}" for p in log.problems),
        elapsed_s=elapsed,
        cycles_per_s=cycles / elapsed if elapsed > 0 else 0.0,
        files=len(files),
        bytes=sum(f.stat().st_size for f in files if f.exists()),
        notes=tuple(notes),
    )


def _index_segments(
    todo: list[IndexTask],
    executor: Executor | None,
    workers: int,
    progress: ProgressCallback | None,
    expected: int,
) -> list[IndexedSegment]:
    """Index each task's segment (on ``executor``, else local processes), reporting the
    decisions written so far against the ``expected`` count."""
    done: list[IndexedSegment] = []
    cycles = 0
    for result in _run(todo, executor, workers):
        done.append(result)
        cycles += result.decisions
        if progress is not None:
            progress(cycles, expected or None)
    return done


def _record(
    target: Path,
    manifest: dict[str, Any],
    known: dict[str, Any],
    done: list[IndexedSegment],
    *,
    settings: dict[str, Any],
    digests: dict[str, Any],
) -> None:
    """Write the segments just indexed into ``known`` and the manifest, then delete the
    files no entry names any more."""
    stale = set(manifest.get("stale_files", []))
    for result in done:
        old = known.get(result.key)
        if old is not None:
            stale.update(set(old["files"]) - set(result.files))
        known[result.key] = asdict(result)
    write_manifest(target, known, settings, digests)
    live = {rel for entry in known.values() for rel in entry["files"]}
    for rel in sorted(stale - live):  # files of an older copy of a segment, or an older index
        remove_own(target, rel)


def _unchanged(entry: dict[str, Any] | None, task: IndexTask) -> bool:
    return (
        entry is not None
        and entry.get("sha256") == task.sha256
        and entry.get("previous_sha256") == task.previous_sha256
    )


def _run(
    tasks: list[IndexTask], executor: Executor | None, workers: int
) -> Iterator[IndexedSegment]:
    """Index each task on ``executor``, in local processes, or here; yields as they finish
    (the first failure is raised as soon as it arrives)."""
    if executor is not None:
        yield from _as_done(executor, tasks)
    elif workers > 1 and len(tasks) > 1:
        with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
            yield from _as_done(pool, tasks)
    else:
        for task in tasks:
            yield index_segment(task)


def _as_done(executor: Executor, tasks: list[IndexTask]) -> Iterator[IndexedSegment]:
    # The longest segments first, so a short one left for last keeps every worker busy.
    ordered = sorted(tasks, key=lambda t: -Path(t.path).stat().st_size)
    futures = [executor.submit(index_segment, t) for t in ordered]
    for future in as_completed(futures):
        yield future.result()
