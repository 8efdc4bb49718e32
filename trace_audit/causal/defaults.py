"""Optional record fields a writer left out, read at their schema defaults.

A robot in another language may omit ``angular`` and mean ``0.0``: the decision view and
the causal graph read each layer with the defaults of ``trace_runtime.records`` filled in.
"""

from __future__ import annotations

import types
from collections.abc import Mapping
from functools import cache
from typing import Union, get_args, get_origin

from pydantic import BaseModel

from trace_runtime.encoding.cycles import Cycle
from trace_runtime.records import MESSAGE_MODELS

__all__ = ["layer_with_defaults", "with_defaults"]


def layer_with_defaults(cycle: Cycle, topic: str) -> object:
    """``cycle.layer(topic)`` with every optional field the writer left out set to its
    schema default (``trace_runtime.records``), as JSON: a robot in another language may
    omit ``angular`` and mean ``0.0``. A warm summary is returned as kept: a field missing
    there was pruned, not defaulted."""
    layer = cycle.layer(topic)
    model = MESSAGE_MODELS.get(topic)
    if topic not in cycle.payloads or model is None:
        return layer
    return with_defaults(model, layer)


def with_defaults(model: type[BaseModel], value: object) -> object:
    """``value`` (plain JSON) with the defaults of ``model``'s omitted optional fields,
    recursively through nested records and lists of them; anything else is left as it is
    (this reads, it does not validate)."""
    if not isinstance(value, Mapping):
        return value
    out = dict(value)
    for key, default, nested in _fields(model):
        if key not in out:
            if default is _REQUIRED:
                continue
            out[key] = default() if callable(default) else default
        if nested is not None:
            item_model, many = nested
            current = out[key]
            if many and isinstance(current, list):
                out[key] = [with_defaults(item_model, item) for item in current]
            elif not many:
                out[key] = with_defaults(item_model, current)
    return out


_REQUIRED = object()


@cache
def _fields(
    model: type[BaseModel],
) -> tuple[tuple[str, object, tuple[type[BaseModel], bool] | None], ...]:
    """(JSON key, default or a factory or ``_REQUIRED``, nested record type) per field."""
    out = []
    for name, info in model.model_fields.items():
        key = info.alias or name
        if info.is_required():
            default: object = _REQUIRED
        elif info.default_factory is not None:
            default = info.default_factory
        else:
            default = _jsonable(info.default)
        out.append((key, default, _nested(info.annotation)))
    return tuple(out)


def _jsonable(value: object) -> object:
    return list(value) if isinstance(value, tuple) else value


def _nested(annotation: object) -> tuple[type[BaseModel], bool] | None:
    """The record type a field holds (and whether it is a list of them), if any."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation, False
    origin = get_origin(annotation)
    if origin is list:
        inner = _nested(get_args(annotation)[0])
        return (inner[0], True) if inner is not None else None
    if origin in (Union, types.UnionType):
        for arg in get_args(annotation):
            found = _nested(arg)
            if found is not None:
                return found
    return None
