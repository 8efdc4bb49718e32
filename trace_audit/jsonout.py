"""Turn library results (pydantic models, dataclasses, paths) into plain JSON data."""

from __future__ import annotations

import dataclasses
import enum
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from trace_runtime.gaps import JSON_INLINE

OMIT_EMPTY = "json_omit_empty"
"""Dataclass field metadata key: leave the field out of JSON while it is empty or None (a
field only some logs fill, e.g. profile 1.1's channels, is absent from the others' JSON)."""


def to_jsonable(value: Any) -> Any:
    """A JSON-ready copy of ``value``: dicts, lists, str, int, float, bool, None."""
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json", by_alias=True)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out: dict[str, Any] = {}
        for f in dataclasses.fields(value):
            item = getattr(value, f.name)
            if f.metadata.get(OMIT_EMPTY) and (item is None or item == ()):
                continue
            if f.metadata.get(JSON_INLINE):
                out.update(to_jsonable(item))
                continue
            out[f.name] = to_jsonable(item)
        return out
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [to_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, bytes):
        return value.hex()
    return value
