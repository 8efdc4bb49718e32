"""The fleet: a Parquet index of every decision, SQL over it with DuckDB, and fan-out of
``index``/``metrics``/``verify`` over a Dask cluster. Needs the ``fleet`` extra (pyarrow,
duckdb, dask); nothing here is imported until a fleet command runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_runtime.lazy import lazy_exports

_EXPORTS = {
    "build_index": "trace_audit.fleet.index",
    "IndexReport": "trace_audit.fleet.index",
    "ColumnSession": "trace_audit.fleet.query",
    "run_query": "trace_audit.fleet.query",
    "find_decisions": "trace_audit.fleet.find",
    "index_robots": "trace_audit.fleet.find",
    "QueryResult": "trace_audit.fleet.query",
    "index_metrics": "trace_audit.fleet.metrics",
    "QueryLimits": "trace_audit.fleet.limits",
    "dask_executor": "trace_audit.fleet.cluster",
}

__all__ = [
    "ColumnSession",
    "IndexReport",
    "QueryResult",
    "build_index",
    "dask_executor",
    "find_decisions",
    "index_metrics",
    "index_robots",
    "run_query",
]

if TYPE_CHECKING:
    from trace_audit.fleet.cluster import dask_executor
    from trace_audit.fleet.find import find_decisions, index_robots
    from trace_audit.fleet.index import IndexReport, build_index
    from trace_audit.fleet.metrics import index_metrics
    from trace_audit.fleet.query import ColumnSession, QueryResult, run_query


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, __all__)
