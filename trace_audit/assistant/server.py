"""The assistant's answers assembled: a question asked in the worker, the integrity of the
log it rests on, the command that reproduces it, and the result as MCP content (the
integrity's line first, so a model that reads only the start still reads it).
"""

from __future__ import annotations

import copy
import json
import re
import shlex
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import anyio.to_thread
from mcp.server.mcpserver.exceptions import ToolError
from mcp.types import CallToolResult, TextContent

from trace_audit.assistant.answers import Answer, Integrity, Truncation
from trace_audit.assistant.bound import MAX_ANSWER_BYTES, bound
from trace_audit.assistant.integrity import VerifyCache, VerifyKeys, integrity_of, unverified
from trace_audit.assistant.roots import Roots, fingerprint
from trace_audit.assistant.worker import CallTimeoutError, Worker
from trace_runtime.errors import TraceError

__all__ = ["Ask", "Assistant", "command_line"]

_WHOLE = 1 << 40
"""The bound of a verify report kept for integrity: never cut (findings past a cut would
be lost)."""

Rests = Literal["log", "index", "listing"]
"""What an answer's integrity is read from: the log's verify, or nothing (an index answer,
a listing of the roots), said as unverified."""


def command_line(command: str, *positional: str | Path, **options: Any) -> str:
    """The ``trace-audit`` command line, shell-quoted, that prints the same ``--json``:
    an option given None or False is left out, True is a flag, a list repeats it."""
    words = ["trace-audit", command, *map(str, positional)]
    for name, value in options.items():
        flag = "--" + name.rstrip("_").replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            words.append(flag)
        elif isinstance(value, list | tuple):
            for item in value:
                words += [flag, str(item)]
        else:
            words += [flag, str(value)]
    return shlex.join([*words, "--json"])


@dataclass(frozen=True, slots=True)
class Ask:
    """One tool call: the question's name and arguments (paths confined), where its
    integrity comes from, and the command that reproduces it."""

    name: str
    args: dict[str, Any]
    reproduce: str
    rests_on: Rests = "log"
    robots: Sequence[str] = field(default=())


class Assistant:
    """The server's state: its roots, the index, the worker and the verify reports."""

    def __init__(
        self, roots: Roots, index: Path | None, timeout_s: float, keys: VerifyKeys | None = None
    ) -> None:
        self.roots = roots
        self.index = index
        self.keys = keys or VerifyKeys()
        """What every verify of this server checks signatures with (none: not checked)."""
        self.worker = Worker(timeout_s)
        self.cache = VerifyCache()

    def log(self, name: str) -> Path:
        """The log ``name`` names under the roots; refused with one clear tool error."""
        return self._confined(name, "log")

    def file(self, name: str, what: str) -> Path:
        """A file (a rules file) under the roots; refused with one clear tool error."""
        return self._confined(name, what)

    def _confined(self, name: str, what: str) -> Path:
        try:
            return self.roots.resolve(name, what)
        except TraceError as err:
            raise ToolError(str(err)) from None

    def index_path(self) -> Path:
        if self.index is None:
            raise ToolError("no fleet index: start the server with --index DIR")
        return self.index

    async def answer(self, ask: Ask) -> CallToolResult:
        """Ask ``ask`` and return the answer, integrity first."""
        _, data, cuts = await self._ask(ask.name, ask.args, MAX_ANSWER_BYTES)
        integrity = await self._integrity(ask)
        return _result(integrity, ask.reproduce, data, cuts)

    async def verify_answer(self, ask: Ask) -> CallToolResult:
        """The verify tool: the report the integrity is read from is the answer's data (one
        verify, not two), cut to the bound after the integrity has read it whole."""
        if ask.robots:
            return await self.answer(ask)
        try:
            report, cached = await self._report(Path(ask.args["log"]))
        except CallTimeoutError as err:
            raise ToolError(f"{err}: ask about one robot, or run trace-audit verify") from None
        integrity = integrity_of(report, (), cached=cached)
        data, cuts = bound(copy.deepcopy(report), tool="verify")
        return _result(integrity, ask.reproduce, data, cuts)

    async def _ask(self, name: str, args: dict[str, Any], limit: int) -> tuple[str, Any, Any]:
        try:
            status, data, cuts = await self.worker.ask(name, args, limit)
        except CallTimeoutError as err:
            raise ToolError(f"{err}: narrow the question (a robot, a window, a time)") from None
        if status != "ok":
            raise ToolError(str(data))
        return status, data, cuts

    async def _integrity(self, ask: Ask) -> Integrity:
        if ask.rests_on == "index":
            return unverified(
                "answered from the fleet index (trace-audit index), not from the logs: ask "
                "verify about the segments a row names to check them"
            )
        if ask.rests_on == "listing":
            return unverified("a listing of what the roots hold; ask verify about a log")
        try:
            report, cached = await self._report(Path(ask.args["log"]))
        except (CallTimeoutError, ToolError) as err:  # the answer stands; its check did not
            return unverified(f"{err}; run trace-audit verify on the log")
        return integrity_of(report, ask.robots, cached=cached)

    async def _report(self, log: Path) -> tuple[dict[str, Any], bool]:
        """The whole log's verify JSON, from this server's cache when the log's files are
        unchanged (and whether it was)."""
        key = await anyio.to_thread.run_sync(fingerprint, log)  # a large root: many stats
        found = self.cache.get(str(log), key)
        if found is not None:
            return found, True
        args = {"log": str(log), **self.keys.args()}
        status, report, _ = await self.worker.ask("verify", args, _WHOLE)
        if status != "ok":
            raise ToolError(f"verify could not read the log: {report}")
        self.cache.put(str(log), key, report)
        return report, False


def _result(integrity: Integrity, reproduce: str, data: Any, cuts: Any) -> CallToolResult:
    """The answer as MCP content: one line of integrity (and of cuts) first, then the whole
    answer as JSON text; the same answer as structured content."""
    envelope = Answer[Any](
        integrity=integrity,
        reproduce=reproduce,
        truncated=[Truncation(**cut) for cut in cuts],
        data=None,
    ).model_dump(mode="json")
    envelope["data"] = data  # as the library's JSON gave it, not re-serialized by a model
    lead = [integrity.summary, f"reproduce: {reproduce}"]
    if cuts:
        lead.append(f"cut to fit the answer's size bound: {_cuts_line(cuts)}")
    if data is None:
        lead.append("the data did not fit the answer's size bound: run the reproduce command")
    text = json.dumps(envelope, ensure_ascii=False)
    return CallToolResult(
        content=[
            TextContent(type="text", text="\n".join(lead)),
            TextContent(type="text", text=text),
        ],
        structured_content=envelope,
    )


_IN_ROBOT = re.compile(r"^robots\[\d+\]\.")


def _cuts_line(cuts: list[dict[str, Any]]) -> str:
    """``amr-1 rows 180 of 3000 (through cycle 179, t 17.9); ...``, then how to ask for the
    rest: the one cut's way, or, when several robots were cut, a robot at a time."""
    said = []
    for c in cuts:
        where = c["path"] or "data"
        if c.get("robot"):  # its robot named, not its index in the answer
            where = f"{c['robot']} {_IN_ROBOT.sub('', where)}"
        through = f" (through {c['through']})" if c.get("through") else ""
        said.append(f"{where} {c['kept']} of {c['total']}{through}")
    robots = {c.get("robot") for c in cuts} - {None}
    rest = cuts[0]["rest"]
    if len(robots) > 1:
        rest = "ask about one robot at a time (each cut's rest in truncated says how)"
    return "; ".join(said) + f"; for the rest: {rest}"
