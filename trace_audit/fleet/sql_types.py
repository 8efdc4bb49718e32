"""The Arrow types the index's columns use (``trace_audit.columns``), named as DuckDB names
them: passed to the column catalogues in place of the ``pyarrow`` module, they give a
table's SQL shape without importing pyarrow (about 0.15 s of a query's start, and pandas
with it once DuckDB sees an Arrow table). ``query.connect`` builds the view of a table
that has no file yet from it and checks each table's files against it."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["bool_", "float64", "int32", "int64", "list_", "map_", "string", "struct"]


def string() -> str:
    return "VARCHAR"


def int64() -> str:
    return "BIGINT"


def int32() -> str:
    return "INTEGER"


def float64() -> str:
    return "DOUBLE"


def bool_() -> str:
    return "BOOLEAN"


def list_(item: str) -> str:
    return f"{item}[]"


def map_(key: str, value: str) -> str:
    return f"MAP({key}, {value})"


def struct(fields: Sequence[tuple[str, str]]) -> str:
    return "STRUCT(" + ", ".join(f"{name} {kind}" for name, kind in fields) + ")"
