"""The fleet index's tables: their Parquet schemas, their version, and what each column means.

docs/fleet.md is the long form; a test checks that every column here is documented there.
Files are Hive-partitioned (``decisions/robot=amr-7/day=2026-11-29/*.parquet``), so ``robot``
and ``day`` are directory names, not columns inside the files; every reader that knows Hive
partitioning (DuckDB, pyarrow.dataset, Spark, Trino) gives them back as columns. ``day`` is
text: the UTC date on a wall clock, ``run-<segment>`` on a sim or monotonic clock
(``rows.partition_of``).
"""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType
from typing import TYPE_CHECKING, TypedDict

from trace_audit.columns import (
    DECISION_WHY,
    channel_columns,
    check_columns,
    decision_columns,
    entity_columns,
    gap_columns,
)

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "INDEX_FORMAT",
    "INDEX_VERSION",
    "PARTITION_COLUMNS",
    "TABLES",
    "parquet_options",
    "schema",
    "sql_columns",
]

INDEX_FORMAT = "trace-fleet-index"
INDEX_VERSION = 3
"""Bumped whenever a column is added, removed or changes meaning; an index of another
version is rebuilt from the logs, not read. 2: the ``channels`` and ``checks`` tables,
``decisions.deviation_unit``, and ``day`` = ``run-<segment>`` on sim and monotonic clocks
(1 put their rows under 1970-01-01). 3: ``decisions.intended_linear`` and
``actual_linear``, a planar robot's linear motion (the rules' ``channel.speed.*``)."""

PARTITION_COLUMNS = ("robot", "day")
TABLES = ("decisions", "entities", "channels", "checks", "gaps", "segments")
_RISING = ("cycle", "t_ns")
"""Integer columns that climb row by row: delta-encoded, not dictionary-encoded."""


class ParquetOptions(TypedDict):
    """Keyword arguments of ``pyarrow.parquet.write_table`` (``parquet_options``)."""

    compression: str
    use_dictionary: list[str]
    column_encoding: dict[str, str]


def parquet_options(shape: pa.Schema) -> ParquetOptions:
    """``pyarrow.parquet.write_table`` settings for one table's file: zstd; dictionaries
    only for top-level strings (names, commands, versions repeat; a dictionary of distinct
    floats and times costs bytes and time); ``cycle`` and ``t_ns`` as deltas. On the bench
    log this writes ~0.66x the bytes of pyarrow's defaults, a little faster (docs/fleet.md);
    any Parquet reader reads both encodings."""
    import pyarrow as pa

    return {
        "compression": "zstd",
        "use_dictionary": [f.name for f in shape if f.type == pa.string()],
        "column_encoding": {name: "DELTA_BINARY_PACKED" for name in _RISING if name in shape.names},
    }


def schema(table: str) -> pa.Schema:
    """The Parquet schema of one table (without the partition columns)."""
    import pyarrow as pa

    columns = _CATALOGUES[table](pa)
    return pa.schema(columns, metadata={"trace.index_version": str(INDEX_VERSION)})


def sql_columns(table: str) -> list[tuple[str, str]]:
    """One table's columns (without the partition columns) with their DuckDB types, from
    the same catalogue as ``schema`` and without importing pyarrow."""
    from trace_audit.fleet import sql_types

    return [(name, str(kind)) for name, kind in _CATALOGUES[table](sql_types)]


_Columns = list[tuple[str, "pa.DataType"]]


_DECISION_COLUMNS = (
    "segment",
    "segment_path",
    "tier",
    "cycle",
    "t_ns",
    "hour",
    "command",
    "previous_command",
    *DECISION_WHY,
    "intended_linear",
    "actual_linear",
    "failed_checks",
    "flags",
    "nearest",
    "scenario",
    "et",
    "et_partial",
    "factors_total",
    "factors_traceable",
    "dr",
    "dr_problems",
    "sealed",
    "seal_verified",
    "integrity_problems",
    "summarized",
    "continuity",
    "tcs",
    "window_ns",
    "gap_ns",
    "missing_cycles",
    "dropped",
    "clock_anomaly",
    "software_version",
    "policy_version",
)
_ENTITY_COLUMNS = (
    "segment",
    "cycle",
    "t_ns",
    "entity",
    "class",
    "confidence",
    "distance",
    "x",
    "y",
    "evidence",
)


def _decision_columns(pa: ModuleType) -> _Columns:
    """One row per decision: what it did, why, and how it scores."""
    return decision_columns(pa, _DECISION_COLUMNS)


def _entity_columns(pa: ModuleType) -> _Columns:
    """One row per perceived entity of a decision."""
    return entity_columns(pa, _ENTITY_COLUMNS)


def _channel_columns(pa: ModuleType) -> _Columns:
    """One row per actuator channel of a decision's execution record (profile 1.1)."""
    return [("segment", pa.string()), *channel_columns(pa)]


def _check_columns(pa: ModuleType) -> _Columns:
    """One row per compliance check of a decision's execution record."""
    return [("segment", pa.string()), *check_columns(pa)]


def _gap_columns(pa: ModuleType) -> _Columns:
    """One row per gap between sealed cycles."""
    return [("segment", pa.string()), *gap_columns(pa)]


def _segment_columns(pa: ModuleType) -> _Columns:
    """One row per segment file indexed."""
    return [
        ("segment", pa.string()),
        ("segment_path", pa.string()),
        ("sha256", pa.string()),
        ("tier", pa.string()),
        ("number", pa.int64()),
        ("start_ns", pa.int64()),
        ("end_ns", pa.int64()),
        ("first_cycle", pa.int64()),
        ("last_cycle", pa.int64()),
        ("cycles", pa.int64()),
        ("bytes", pa.int64()),
        ("finished", pa.bool_()),
        ("seal_status", pa.string()),
        ("integrity_failed", pa.int64()),
        ("software_version", pa.string()),
        ("policy_version", pa.string()),
        ("period_ns", pa.int64()),
    ]


_CATALOGUES: dict[str, Callable[[ModuleType], _Columns]] = {
    "decisions": _decision_columns,
    "entities": _entity_columns,
    "channels": _channel_columns,
    "checks": _check_columns,
    "gaps": _gap_columns,
    "segments": _segment_columns,
}
"""Each table's columns, given ``pyarrow`` (its schema) or ``sql_types`` (its SQL shape)."""
