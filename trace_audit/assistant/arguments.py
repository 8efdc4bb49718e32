"""A tool's arguments checked before it runs: a refusal is one line that names the argument
and what it takes, and an argument the tool does not take is refused, not ignored.

The SDK validates arguments with pydantic and hands the model pydantic's report: several
lines per argument, the union's every branch, a link to pydantic's docs. A model reads one
line better, and a misspelt argument (``robots`` for ``robot``) silently ignored would
answer a question about every robot as if it were about one. The tools' published input
schemas say the same (``additionalProperties: false``), so a client can check first.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from mcp.server.mcpserver.exceptions import ToolError
from mcp.server.mcpserver.tools import Tool
from mcp.server.mcpserver.utilities.func_metadata import FuncMetadata
from mcp.types import ToolAnnotations
from pydantic import ValidationError

if TYPE_CHECKING:
    from mcp.server.mcpserver.context import Context

__all__ = ["CheckedTool", "refusal"]

_KINDS = {
    "string": ("a string", "strings"),
    "integer": ("an integer", "integers"),
    "number": ("a number", "numbers"),
    "boolean": ("true or false", "booleans"),
    "null": ("null", "nulls"),
    "object": ("an object", "objects"),
}
_SHOWN = 40
"""Characters of a refused value quoted back (it is the caller's, so it may be long)."""


class CheckedTool(Tool):
    """A tool whose arguments are checked (``refusal``) before the SDK's own validation."""

    @classmethod
    def of(
        cls, fn: Callable[..., Any], name: str, annotations: ToolAnnotations, description: str
    ) -> CheckedTool:
        """The tool of ``fn``, with structured output and a schema that takes no other
        argument than its own."""
        tool = cls.from_function(
            fn,
            name=name,
            description=description,
            annotations=annotations,
            structured_output=True,
        )
        assert isinstance(tool, CheckedTool)  # from_function builds ``cls``
        tool.parameters["additionalProperties"] = False
        return tool

    async def run(
        self, arguments: dict[str, Any], context: Context[Any, Any], convert_result: bool = False
    ) -> Any:
        refused = refusal(self.name, self.parameters, arguments, self.fn_metadata)
        if refused is not None:  # the SDK's prefix, as every other error of a tool reads
            raise ToolError(f"Error executing tool {self.name}: {refused}")
        return await super().run(arguments, context, convert_result)


def refusal(
    tool: str, schema: dict[str, Any], arguments: dict[str, Any], metadata: FuncMetadata
) -> str | None:
    """Why ``arguments`` are refused, in one line, or None when the tool takes them."""
    properties: dict[str, Any] = schema.get("properties", {})
    unknown = [name for name in arguments if name not in properties]
    if unknown:
        s = "s" if len(unknown) > 1 else ""
        return f"unknown argument{s} {', '.join(unknown)}: {tool} takes {', '.join(properties)}"
    try:
        metadata.validate_arguments(arguments)
    except ValidationError as err:
        return _said(err, properties, schema.get("required", []), arguments)
    return None


def _said(
    err: ValidationError,
    properties: dict[str, Any],
    required: Sequence[str],
    arguments: dict[str, Any],
) -> str:
    """Each argument the validator refused, once, with what it takes."""
    said: dict[str, str] = {}
    for error in err.errors():
        name = str(error["loc"][0]) if error["loc"] else ""
        if name in said:
            continue
        if name not in properties:  # not one argument's (never seen: said plainly)
            said[name] = f"arguments: {error['msg']}"
        elif error["type"] == "missing":
            said[name] = f"argument {name} is missing (required: {', '.join(required)})"
        else:
            got = _shown(arguments.get(name))
            said[name] = f"argument {name} takes {_expected(properties[name])}, not {got}"
    return "; ".join(said.values())


def _expected(schema: dict[str, Any]) -> str:
    """What an argument's JSON schema takes, in words: ``a list of strings or null``."""
    options = schema.get("anyOf", [schema])
    return " or ".join(_kind(option) for option in options)


def _kind(schema: dict[str, Any]) -> str:
    if "enum" in schema:
        return "one of " + ", ".join(json.dumps(v) for v in schema["enum"])
    if "const" in schema:
        return json.dumps(schema["const"])
    kind = schema.get("type")
    if kind == "array":
        item = schema.get("items", {}).get("type")
        return f"a list of {_KINDS[item][1]}" if item in _KINDS else "a list"
    words = _KINDS[kind][0] if kind in _KINDS else "a value"
    low, high = schema.get("minimum"), schema.get("maximum")
    if low is not None and high is not None:
        return f"{words} from {low} to {high}"
    if low is not None:
        return f"{words} of at least {low}"
    return words


def _shown(value: Any) -> str:
    """A refused value as JSON on one line, shortened."""
    text = json.dumps(value, default=str)  # ASCII: no line separator
    return text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "..."
