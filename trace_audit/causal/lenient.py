"""Lenient access to a layer's plain JSON: a value of the wrong type reads as absent.

The one owner of reading untrusted, decoded JSON without validating it: the decision view,
the causal graph, the layer tables, the fleet index, the rules' signals and the incident
report read what was logged, however damaged or partial (a warm summary, another writer's
record), through these functions.

"A number" has two meanings here, and each reader says which one it means:

- ``as_float``: **a bool is not a number** (``true`` is a flag, not 1.0). What a value shown
  as a quantity needs: a score, a confidence, a position, a factor plotted over time.
- ``as_number_or_flag``: **a bool counts as 0.0 or 1.0**. What a column of numbers a query
  or a rule compares needs: a factor ``obstacle_seen: true`` is 1.0 in the fleet index's
  ``lead_value`` and in a rule's signal.

Neither ever raises: anything else (a string, null, a list, an object) is None.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

__all__ = ["as_float", "as_list", "as_mapping", "as_number_or_flag", "as_str", "mappings"]


def as_mapping(value: object) -> Mapping[str, object] | None:
    """``value`` when it is a JSON object, else None."""
    return value if isinstance(value, Mapping) else None


def mappings(value: object) -> Iterable[Mapping[str, object]]:
    """The JSON objects in ``value`` when it is a list (anything else in it is skipped)."""
    if isinstance(value, list):
        return [v for v in value if isinstance(v, Mapping)]
    return ()


def as_str(value: object) -> str | None:
    """``value`` when it is a string, else None."""
    return value if isinstance(value, str) else None


def as_float(value: object) -> float | None:
    """``value`` as a float when it is a JSON number, else None: a bool is not a number."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def as_number_or_flag(value: object) -> float | None:
    """``value`` as a float when it is a JSON number or a bool (``true`` 1.0, ``false``
    0.0), else None."""
    # The exact types first: this runs for every number of every row the fleet index builds.
    if type(value) is float:
        return value
    if type(value) is int or type(value) is bool:
        return float(value)
    return float(value) if isinstance(value, int | float) else None


def as_list(value: object) -> list[object]:
    """``value`` when it is a JSON array, else an empty list (a string is not a list of
    its characters, an object not a list of its keys)."""
    return value if isinstance(value, list) else []
