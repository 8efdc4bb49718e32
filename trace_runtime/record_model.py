"""The base every TRACE record model stands on: how a record validates (frozen, no extra
fields, no NaN or infinity; ``RecordError`` naming the first bad field), how its docstring
lists its fields' meanings for ``help()``, and ``validate_record`` for data that may be a
dict or a model already. The models themselves are ``records``.
"""

from __future__ import annotations

import inspect
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, GetJsonSchemaHandler, ValidationError
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import CoreSchema

from trace_runtime.errors import RecordError

__all__ = ["RecordModel", "Stamp", "validate_record"]


class RecordModel(BaseModel):
    """Base of every TRACE record: frozen, no extra fields, no NaN or infinity, built
    from aliases or names; bad fields raise ``RecordError``."""

    model_config = ConfigDict(
        frozen=True,
        extra="forbid",
        allow_inf_nan=False,
        populate_by_name=True,
        ser_json_inf_nan="null",
    )

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as err:
            raise RecordError(_describe(type(self).__name__, err)) from err

    # Tell pydantic this __init__ only wraps errors: nested records validated from dicts then
    # stay on pydantic's fast path instead of calling back into Python once per object.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    @classmethod
    def __pydantic_init_subclass__(cls, **kwargs: Any) -> None:
        super().__pydantic_init_subclass__(**kwargs)
        cls.__doc__ = _with_field_docs(cls)

    @classmethod
    def __get_pydantic_json_schema__(
        cls, core_schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        # The JSON Schemas keep the class's own docstring: their fields carry the meanings.
        schema = handler.resolve_ref_schema(handler(core_schema))
        own = cls.__dict__.get("_own_doc")
        if own:
            schema["description"] = own
        return schema


def _with_field_docs(model: type[BaseModel]) -> str:
    """The class docstring followed by one line per field (JSON name, type, default,
    meaning), so ``help()`` and IDEs show what each field means rather than pydantic's
    generic text. The meanings are the fields' ``description``s, the same text that the
    JSON Schemas carry."""
    head = inspect.cleandoc(model.__dict__.get("__doc__") or "")
    type.__setattr__(model, "_own_doc", head)
    lines = [head, "", "Fields (JSON name: type = default, meaning):", ""]
    for name, info in model.model_fields.items():
        key = info.alias or name
        shown = key if key == name else f"{key} (Python: {name})"
        kind = _type_text(info.annotation)
        required = info.is_required()
        default = "" if required else " = " + repr(info.get_default(call_default_factory=True))
        lines.append(f"    {shown}: {kind}{default}")
        lines.append(f"        {info.description or '(undocumented)'}")
    return "\n".join(lines) + "\n"


def _type_text(annotation: Any) -> str:
    text = getattr(annotation, "__name__", None) if isinstance(annotation, type) else None
    return text or str(annotation).replace("trace_runtime.records.", "").replace("typing.", "")


def _describe(model: str, err: ValidationError) -> str:
    first = err.errors()[0]
    where = ".".join(str(p) for p in first["loc"]) or "<root>"
    more = f" (and {err.error_count() - 1} more)" if err.error_count() > 1 else ""
    return f"invalid {model}: {where}: {first['msg']}{more}"


class Stamp(RecordModel):
    """What every ``/trace`` message begins with: the cycle it belongs to and its time."""

    cycle: int = Field(ge=0, description="the cycle number, +1 per cycle begun (PROFILE §4)")
    t_ns: int = Field(ge=0, description="the cycle's time in ns; the message's MCAP log_time")


R = TypeVar("R", bound=RecordModel)


def validate_record(model: type[R], data: Any) -> R:
    """Validate ``data`` (a dict or already a model) as ``model``; raise ``RecordError``."""
    if isinstance(data, model):
        return data
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise RecordError(_describe(model.__name__, err)) from err
