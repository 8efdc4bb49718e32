"""The Arrow columns of a log's tables, each written once.

Two products hold the same tables: the layer tables (``trace_audit.layers``: a log's
decisions, entities, actuator channels, checks and gaps as ``pyarrow`` tables, for
notebooks) and the fleet index (``trace_audit.fleet.tables``: the same rows as Parquet
files, with scores and partitions added). Both take their columns from here, so a column
has one name and one type wherever it appears, and docs/fleet.md describes both.

- ``channel_columns``, ``check_columns`` and ``gap_columns`` are a row's columns after the
  key that says whose it is (``robot`` in a layer table, ``segment`` in the index);
  ``gap_row`` is a gap's values in ``gap_columns``' order, for both.
- ``decision_columns`` and ``entity_columns`` give the columns a product names, from one
  catalogue per table: the index keeps columns the layer table has not (scores, ``hour``,
  ``distance``) and the other way round (``score``, ``rationale``, ``z``, ``frame``).

``pa`` is the ``pyarrow`` module, passed in: pyarrow comes with the ``fleet`` extra, and
each product says how to get it.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType
from typing import TYPE_CHECKING

from trace_runtime.gaps import Gap

if TYPE_CHECKING:  # the fleet extra; the products import it when they build a table
    import pyarrow

__all__ = [
    "DECISION_WHY",
    "channel_columns",
    "check_columns",
    "decision_columns",
    "entity_columns",
    "factor_struct",
    "gap_columns",
    "gap_row",
]

Columns = list[tuple[str, "pyarrow.DataType"]]
"""Named Arrow column types, in a table's order."""

DECISION_WHY = (
    "lead_factor",
    "lead_value",
    "lead_text",
    "lead_unit",
    "factors",
    "alternatives",
    "counterfactuals",
    "deviation",
    "deviation_unit",
)
"""Why a decision was taken and how it went, in the order both decision tables keep."""


def decision_columns(pa: ModuleType, names: Sequence[str]) -> Columns:
    """The decision table's columns called ``names``, in that order."""
    strings = pa.list_(pa.string())
    types = {
        "robot": pa.string(),
        "segment": pa.string(),
        "segment_path": pa.string(),
        "tier": pa.string(),
        "cycle": pa.int64(),
        "t_ns": pa.int64(),
        "hour": pa.string(),
        "command": pa.string(),
        "previous_command": pa.string(),
        "score": pa.float64(),
        "rationale": pa.string(),
        "truncated": pa.bool_(),
        "lead_factor": pa.string(),
        "lead_value": pa.float64(),
        "lead_text": pa.string(),
        "lead_unit": pa.string(),
        "factors": pa.list_(factor_struct(pa)),
        "alternatives": pa.int32(),
        "counterfactuals": pa.int32(),
        "deviation": pa.float64(),
        "deviation_unit": pa.string(),
        "intended_linear": pa.float64(),
        "actual_linear": pa.float64(),
        "failed_checks": strings,
        "flags": strings,
        "nearest": pa.map_(pa.string(), pa.float64()),
        "scenario": pa.string(),
        "et": pa.float64(),
        "et_partial": pa.float64(),
        "factors_total": pa.int32(),
        "factors_traceable": pa.int32(),
        "dr": pa.bool_(),
        "dr_problems": strings,
        "sealed": pa.bool_(),
        "seal_verified": pa.bool_(),
        "integrity_problems": strings,
        "summarized": pa.bool_(),
        "continuity": pa.float64(),
        "tcs": pa.float64(),
        "window_ns": pa.int64(),
        "gap_ns": pa.int64(),
        "missing_cycles": pa.int64(),
        "dropped": pa.int64(),
        "clock_anomaly": pa.bool_(),
        "software_version": pa.string(),
        "policy_version": pa.string(),
    }
    return [(name, types[name]) for name in names]


def entity_columns(pa: ModuleType, names: Sequence[str]) -> Columns:
    """The entity table's columns called ``names``, in that order."""
    types = {
        "robot": pa.string(),
        "segment": pa.string(),
        "cycle": pa.int64(),
        "t_ns": pa.int64(),
        "entity": pa.string(),
        "class": pa.string(),
        "confidence": pa.float64(),
        "distance": pa.float64(),
        "x": pa.float64(),
        "y": pa.float64(),
        "z": pa.float64(),
        "frame": pa.string(),
        "evidence": pa.int32(),
    }
    return [(name, types[name]) for name in names]


def factor_struct(pa: ModuleType) -> pyarrow.StructType:
    """A factor as a column value: the same in the layer tables and the fleet index."""
    return pa.struct(
        [
            ("node", pa.string()),
            ("name", pa.string()),
            ("value", pa.float64()),
            ("text", pa.string()),
            ("unit", pa.string()),
        ]
    )


def channel_columns(pa: ModuleType) -> Columns:
    """An actuator channel row's columns after the key saying whose it is."""
    return [
        ("cycle", pa.int64()),
        ("t_ns", pa.int64()),
        ("channel", pa.string()),
        ("intended", pa.float64()),
        ("actual", pa.float64()),
        ("deviation", pa.float64()),
        ("unit", pa.string()),
        ("deviation_unit", pa.string()),
    ]


def check_columns(pa: ModuleType) -> Columns:
    """An execution check row's columns after its key."""
    return [
        ("cycle", pa.int64()),
        ("t_ns", pa.int64()),
        ("rule", pa.string()),
        ("passed", pa.bool_()),
        ("value", pa.float64()),
        ("limit", pa.float64()),
        ("detail", pa.string()),
    ]


def gap_columns(pa: ModuleType) -> Columns:
    """A gap row's columns after its key (``trace_runtime.gaps.Gap``'s fields)."""
    return [
        ("after_cycle", pa.int64()),
        ("after_t_ns", pa.int64()),
        ("before_cycle", pa.int64()),
        ("before_t_ns", pa.int64()),
        ("period_ns", pa.int64()),
        ("gap_ns", pa.int64()),
        ("missing_cycles", pa.int64()),
        ("declared_dropped", pa.int64()),
    ]


def gap_row(key: str, gap: Gap) -> tuple[str, int, int, int, int, int, int, int, int | None]:
    """A gap's row: its ``key`` (robot or segment), then ``gap_columns``' values."""
    return (
        key,
        gap.after_cycle,
        gap.after_t_ns,
        gap.before_cycle,
        gap.before_t_ns,
        gap.period_ns,
        gap.gap_ns,
        gap.missing_cycles,
        gap.declared_dropped,
    )
