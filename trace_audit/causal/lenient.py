"""Lenient access to a layer's plain JSON: a value of the wrong type reads as absent.

The decision view and the causal graph read what was logged, however damaged or partial
(a warm summary, another writer's record), without validating it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["as_float", "as_mapping", "as_str", "mappings"]


def as_mapping(value: Any) -> Mapping[str, Any] | None:
    """``value`` when it is a JSON object, else None."""
    return value if isinstance(value, Mapping) else None


def mappings(value: Any) -> Iterable[Mapping[str, Any]]:
    """The JSON objects in ``value`` when it is a list (anything else in it is skipped)."""
    if isinstance(value, list):
        return [v for v in value if isinstance(v, Mapping)]
    return ()


def as_str(value: Any) -> str | None:
    """``value`` when it is a string, else None."""
    return value if isinstance(value, str) else None


def as_float(value: Any) -> float | None:
    """``value`` as a float when it is a JSON number (not a boolean), else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)
