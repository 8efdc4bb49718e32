"""One segment of the fleet index, the task a local process or a Dask worker runs: its chain
position and digests (``IndexTask``), scored through metrics into its rows, written as one
Parquet file per table and day (``index_segment``), and what it wrote (``IndexedSegment``,
the manifest's entry)."""

from __future__ import annotations

import contextlib
import gc
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from trace_audit.fleet.folder import write_table_file
from trace_audit.fleet.rows import ROW_TABLES, SegmentRows, day_of
from trace_audit.fleet.tables import parquet_options
from trace_audit.metrics import MetricsConfig, score_segment
from trace_runtime.reading.reader import Segment, open_segment

if TYPE_CHECKING:  # the fleet extra, imported by the functions that build the tables
    import pyarrow as pa

__all__ = ["IndexTask", "IndexedSegment", "index_segment"]


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


def index_segment(task: IndexTask) -> IndexedSegment:
    """Score one segment through metrics and write its rows, one Parquet file per table and
    day; safe to run on a Dask worker that sees the same paths (shared storage)."""
    import pyarrow.parquet as pq

    segment = open_segment(task.path)
    rows = SegmentRows(segment, previous_command=_last_command(task.previous), run=task.run)
    config = MetricsConfig(
        gap_tolerance=task.gap_tolerance, sensor_window=task.sensor_window, max_listed=0
    )
    with _CYCLIC_GC.paused():
        score_segment(task.path, task.previous, config, rows)
        tables = {name: rows.table(name) for name in ROW_TABLES}
    out = Path(task.out)
    robot = segment.session.robot_id
    stem = task.key.replace("/", "_")
    files: list[str] = []
    tables["segments"] = _segment_row(segment, rows, task.sha256, task.run)
    for name, (table, days) in tables.items():
        for day in sorted(set(days)):
            part = table if len(set(days)) == 1 else _rows_of_day(table, days, day)
            rel = f"{name}/robot={robot}/day={day}/{stem}.parquet"
            options = parquet_options(part.schema)
            write_table_file(out, rel, partial(pq.write_table, part, **options))
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


class _CyclicGcPause:
    """The cyclic garbage collector paused while a segment's rows are built.

    The rows (a tuple of scalars per decision, entity and check: ~240,000 for an hour of a
    sim log) live until their tables are written, and every collection the allocations
    trigger walks all of them again: 12% of a segment's build (5.7 -> 5.0 s CPU, in
    process). Nothing built here is cyclic (parsed JSON, tuples of scalars), so reference
    counting frees it all. A Dask worker runs tasks in threads, so the pause is counted: the
    collector comes back, if it was on, when the last task running leaves.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._holders = 0
        self._was_enabled = False

    @contextlib.contextmanager
    def paused(self) -> Iterator[None]:
        with self._lock:
            if self._holders == 0:
                self._was_enabled = gc.isenabled()
                gc.disable()
            self._holders += 1
        try:
            yield
        finally:
            with self._lock:
                self._holders -= 1
                if self._holders == 0 and self._was_enabled:
                    gc.enable()


_CYCLIC_GC = _CyclicGcPause()


def _rows_of_day(table: pa.Table, days: list[str], day: str) -> pa.Table:
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
) -> tuple[pa.Table, list[str]]:
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
