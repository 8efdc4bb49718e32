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
Each segment is scored by ``trace_audit.metrics.score_segment`` (one task, on a local
process or a Dask worker), which writes its own files; the manifest is replaced last.
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from trace_audit.fleet.folder import (
    MANIFEST,
    check_target,
    index_lock,
    load_manifest,
    remove_own,
    write_manifest,
    write_table_file,
)
from trace_audit.fleet.rows import ROW_TABLES, SegmentRows, day_of, partition_of
from trace_audit.fleet.tables import INDEX_VERSION, parquet_options
from trace_audit.metrics import MetricsConfig, score_segment
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.reading.copies import preferred_copies
from trace_runtime.reading.logset import Log, open_logs
from trace_runtime.reading.reader import Segment, open_segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tiers.catalog import file_digest

__all__ = ["MANIFEST", "IndexReport", "build_index", "index_segment", "load_manifest"]

ProgressCallback = Callable[[int, int | None], None]


@dataclass(frozen=True, slots=True)
class IndexTask:
    """One segment to index: its chain position, file, digests and where to write."""

    key: str
    path: str
    previous: str | None
    sha256: str
    previous_sha256: str | None
    out: str
    gap_tolerance: float
    sensor_window: int
    run: str | None = None
    """The ``day`` partition of every row on a sim or monotonic clock; None: by UTC day."""


@dataclass(frozen=True, slots=True)
class IndexedSegment:
    """What indexing one segment wrote (a manifest entry)."""

    key: str
    robot: str
    path: str
    sha256: str
    previous_sha256: str | None
    decisions: int
    entities: int
    gaps: int
    files: tuple[str, ...]
    """Written files, relative to the index directory."""


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


# --- one segment (runs on a worker) ----------------------------------------------------------


def index_segment(task: IndexTask) -> IndexedSegment:
    """Score one segment through metrics and write its rows, one Parquet file per table and
    day; safe to run on a Dask worker that sees the same paths (shared storage)."""
    import pyarrow.parquet as pq

    segment = open_segment(task.path)
    rows = SegmentRows(segment, previous_command=_last_command(task.previous), run=task.run)
    config = MetricsConfig(
        gap_tolerance=task.gap_tolerance, sensor_window=task.sensor_window, max_listed=0
    )
    score_segment(task.path, task.previous, config, rows)
    out = Path(task.out)
    robot = segment.session.robot_id
    stem = task.key.replace("/", "_")
    files: list[str] = []
    tables = {name: rows.table(name) for name in ROW_TABLES}
    tables["segments"] = _segment_row(segment, rows, task.sha256, task.run)
    for name, (table, days) in tables.items():
        for day in sorted(set(days)):
            part = table if len(set(days)) == 1 else _rows_of_day(table, days, day)
            rel = f"{name}/robot={robot}/day={day}/{stem}.parquet"
            options = parquet_options(part.schema)
            write_table_file(out, rel, lambda f, p=part, o=options: pq.write_table(p, f, **o))
            files.append(rel)
    return IndexedSegment(
        key=task.key,
        robot=robot,
        path=task.path,
        sha256=task.sha256,
        previous_sha256=task.previous_sha256,
        decisions=tables["decisions"][0].num_rows,
        entities=tables["entities"][0].num_rows,
        gaps=tables["gaps"][0].num_rows,
        files=tuple(files),
    )


def _rows_of_day(table: Any, days: list[str], day: str) -> Any:
    import pyarrow as pa

    return table.filter(pa.array([d == day for d in days]))


def _last_command(previous: str | None) -> str | None:
    """The command in force when the segment opened: the previous segment's last action."""
    if previous is None:
        return None
    for cycle in open_segment(previous).iter_cycles(reverse=True):
        action = cycle.layer("/trace/action")
        if isinstance(action, dict) and action.get("command"):
            return str(action["command"])
    return None


def _segment_row(
    segment: Segment, rows: SegmentRows, sha256: str, run: str | None
) -> tuple[Any, list[str]]:
    import pyarrow as pa

    from trace_audit.fleet.tables import schema

    info, session = segment.info, segment.session
    decisions = rows.decisions
    row = {
        "segment": segment.path.name,
        "segment_path": str(segment.path),
        "sha256": sha256,
        "tier": session.tier,
        "number": session.segment,
        "start_ns": info.start_ns,
        "end_ns": info.end_ns,
        "first_cycle": rows.first_cycle,
        "last_cycle": rows.last_cycle,
        "cycles": decisions,
        "bytes": info.bytes,
        "finished": info.finished,
        "seal_status": "clean" if rows.integrity_failed == 0 else "findings",
        "integrity_failed": rows.integrity_failed,
        "software_version": session.software_version,
        "policy_version": session.policy_version,
        "period_ns": session.period_ns,
    }
    table = pa.Table.from_pylist([row], schema=schema("segments"))
    return table, [run or day_of(info.start_ns)]


# --- the whole index ---------------------------------------------------------------------------


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


# --- one segment per chain position ------------------------------------------------------------


def _position(segment: Segment) -> str:
    """The index key of a segment's chain position: ``robot/segment/first cycle``."""
    session = segment.session
    return f"{session.robot_id}/{session.segment:06d}/{session.first_cycle}"


def _identity(segment: Segment) -> str:
    """What tells two recordings apart: the bytes of the first seal (its chain link and
    layer digests); two copies of one segment, however truncated, share it."""
    for cycle in segment.iter_cycles():
        sealed = cycle.payloads.get(TOPIC_SEAL)
        if sealed is not None:
            return hashlib.sha256(sealed).hexdigest()
    return f"empty@{segment.info.start_ns}"


def _different_logs(a: str | Path, b: str | Path, key: str) -> UsageError:
    robot, number, cycle = key.split("/")
    return UsageError(
        f"{a} and {b} are two different logs of robot {robot} at segment {int(number)} "
        f"(cycle {cycle}); index them into separate indexes or give the robots distinct ids"
    )


def _open_refusing_forks(paths: Sequence[str | Path]) -> Log:
    # The index refuses two recordings at one position itself, naming both (one line):
    # the readers' warning about the same fork would say it twice.
    forks = logging.getLogger("trace_runtime.forks")
    was, forks.disabled = forks.disabled, True
    try:
        return open_logs(paths)
    finally:
        forks.disabled = was


def _one_copy_each(log: Log) -> tuple[set[Path], list[str]]:
    """Inputs holding one chain position twice: the same segment in two copies keeps the
    best (the others are named in a note); two different logs are refused (exit 2), since
    one position holds one segment's rows."""
    by_key: dict[str, list[Segment]] = {}
    for segment in [*log.segments, *log.shadowed]:
        by_key.setdefault(_position(segment), []).append(segment)
    left_out: set[Path] = set()
    notes: list[str] = []
    for key, copies in by_key.items():
        if len(copies) < 2:
            continue
        first = _identity(copies[0])
        for other in copies[1:]:
            if _identity(other) != first:
                raise _different_logs(copies[0].path, other.path, key)
        best = copies[0]  # the copy every reader reads (copies.preferred_copies)
        for copy in copies:
            if copy is not best:
                left_out.add(copy.path)
                kind = "a recovered (truncated) copy" if not copy.info.finished else "a copy"
                notes.append(f"{copy.path}: {kind} of {best.path}, which is indexed")
    return left_out, notes


def _against_manifest(task: IndexTask, entry: dict[str, Any] | None) -> str | None:
    """A position the index already holds from another file that is still there: refused
    when it is another log; a note (and the task dropped) when the indexed copy is the
    better one. None: index the task."""
    if entry is None or entry.get("path") == task.path or not Path(entry["path"]).is_file():
        return None  # new, the same file, or moved (compacted into another tier)
    try:
        held = open_segment(entry["path"])
    except LogReadError:
        return None  # the indexed file is no longer readable: the new copy replaces it
    new = open_segment(task.path)
    if _identity(held) != _identity(new):
        raise _different_logs(entry["path"], task.path, task.key)
    (read,), _ = preferred_copies([held, new])
    if read is held:
        return f"{task.path}: a copy of {entry['path']}, which stays indexed"
    return None


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
                    key=_position(segment),
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
        note = _against_manifest(task, known.get(task.key))
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
    check_target(target)  # a folder that is not ours is refused before the lock is made in it
    with index_lock(target):
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
    log = _open_refusing_forks(paths)
    cache: dict[str, Any] = dict(manifest.get("digests", {}))
    left_out, notes = _one_copy_each(log)
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
