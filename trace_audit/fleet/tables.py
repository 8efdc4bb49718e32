"""The fleet index's tables: their Parquet schemas, their version, and what each column means.

docs/fleet.md is the long form; a test checks that every column here is documented there.
Files are Hive-partitioned (``decisions/robot=amr-7/day=2026-11-29/*.parquet``), so ``robot``
and ``day`` are directory names, not columns inside the files; every reader that knows Hive
partitioning (DuckDB, pyarrow.dataset, Spark, Trino) gives them back as columns. ``day`` is
text: the UTC date on a wall clock, ``run-<segment>`` on a sim or monotonic clock
(``rows.partition_of``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from trace_audit.layers import channel_columns, check_columns, factor_struct

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "INDEX_FORMAT",
    "INDEX_VERSION",
    "PARTITION_COLUMNS",
    "TABLES",
    "parquet_options",
    "schema",
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


def parquet_options(shape: pa.Schema) -> dict[str, Any]:
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

    columns = {
        "decisions": _decision_columns,
        "entities": _entity_columns,
        "channels": _channel_columns,
        "checks": _check_columns,
        "gaps": _gap_columns,
        "segments": _segment_columns,
    }[table]()
    return pa.schema(columns, metadata={"trace.index_version": str(INDEX_VERSION)})


_Columns = list[tuple[str, "pa.DataType"]]


def _decision_columns() -> _Columns:
    """One row per decision: what it did, why, and how it scores."""
    import pyarrow as pa

    factor = factor_struct(pa)
    strings = pa.list_(pa.string())
    return [
        ("segment", pa.string()),
        ("segment_path", pa.string()),
        ("tier", pa.string()),
        ("cycle", pa.int64()),
        ("t_ns", pa.int64()),
        ("hour", pa.string()),
        ("command", pa.string()),
        ("previous_command", pa.string()),
        ("lead_factor", pa.string()),
        ("lead_value", pa.float64()),
        ("lead_text", pa.string()),
        ("lead_unit", pa.string()),
        ("factors", pa.list_(factor)),
        ("alternatives", pa.int32()),
        ("counterfactuals", pa.int32()),
        ("deviation", pa.float64()),
        ("deviation_unit", pa.string()),
        ("intended_linear", pa.float64()),
        ("actual_linear", pa.float64()),
        ("failed_checks", strings),
        ("flags", strings),
        ("nearest", pa.map_(pa.string(), pa.float64())),
        ("scenario", pa.string()),
        ("et", pa.float64()),
        ("et_partial", pa.float64()),
        ("factors_total", pa.int32()),
        ("factors_traceable", pa.int32()),
        ("dr", pa.bool_()),
        ("dr_problems", strings),
        ("sealed", pa.bool_()),
        ("seal_verified", pa.bool_()),
        ("integrity_problems", strings),
        ("summarized", pa.bool_()),
        ("continuity", pa.float64()),
        ("tcs", pa.float64()),
        ("window_ns", pa.int64()),
        ("gap_ns", pa.int64()),
        ("missing_cycles", pa.int64()),
        ("dropped", pa.int64()),
        ("clock_anomaly", pa.bool_()),
        ("software_version", pa.string()),
        ("policy_version", pa.string()),
    ]


def _entity_columns() -> _Columns:
    """One row per perceived entity of a decision."""
    import pyarrow as pa

    return [
        ("segment", pa.string()),
        ("cycle", pa.int64()),
        ("t_ns", pa.int64()),
        ("entity", pa.string()),
        ("class", pa.string()),
        ("confidence", pa.float64()),
        ("distance", pa.float64()),
        ("x", pa.float64()),
        ("y", pa.float64()),
        ("evidence", pa.int32()),
    ]


def _channel_columns() -> _Columns:
    """One row per actuator channel of a decision's execution record (profile 1.1)."""
    import pyarrow as pa

    return [("segment", pa.string()), *channel_columns(pa)]


def _check_columns() -> _Columns:
    """One row per compliance check of a decision's execution record."""
    import pyarrow as pa

    return [("segment", pa.string()), *check_columns(pa)]


def _gap_columns() -> _Columns:
    """One row per gap between sealed cycles."""
    import pyarrow as pa

    return [
        ("segment", pa.string()),
        ("after_cycle", pa.int64()),
        ("after_t_ns", pa.int64()),
        ("before_cycle", pa.int64()),
        ("before_t_ns", pa.int64()),
        ("period_ns", pa.int64()),
        ("gap_ns", pa.int64()),
        ("missing_cycles", pa.int64()),
        ("declared_dropped", pa.int64()),
    ]


def _segment_columns() -> _Columns:
    """One row per segment file indexed."""
    import pyarrow as pa

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
