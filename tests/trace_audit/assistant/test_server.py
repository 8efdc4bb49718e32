"""``trace-audit mcp`` from the outside: a real server process, asked over stdio by the MCP
SDK's own client (``mcp.client.stdio`` + ``ClientSession``), as an assistant asks it."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import anyio
import pytest

from tests.outside import REPO, cli, snapshot
from tests.trace_audit.conftest import rewrite_segment

pytest.importorskip("mcp")

from mcp import ClientSession  # noqa: E402 - after the skip: the extra may be missing
from mcp.client.stdio import StdioServerParameters, stdio_client  # noqa: E402
from mcp.types import CallToolResult, TextContent  # noqa: E402

T = TypeVar("T")
_SIM_ACTION = "STOP"


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A root with a simulated robot's log (sim/, 100 cycles a scenario) and a tampered
    copy of it (tampered/: one action message's rationale changed after it was sealed)."""
    from sim.runner import RunConfig, run

    base = tmp_path_factory.mktemp("mcp") / "root"
    run(RunConfig(out=base / "sim", scenario="all", cycles=100, seed=42))
    segment = next((base / "sim" / "hot").glob("*.mcap"))
    changed = {"done": False}

    def tamper(msg: Any) -> bytes:
        if msg.topic == "/trace/action" and not changed["done"] and b'"rationale"' in msg.data:
            changed["done"] = True
            record = json.loads(msg.data)
            record["rationale"] = "nothing was in the way"
            return json.dumps(record).encode()
        return bytes(msg.data)

    (base / "tampered").mkdir()
    rewrite_segment(segment, base / "tampered" / segment.name, tamper)
    assert changed["done"]
    return base


def _serve(
    roots: list[Path], ask: Callable[[ClientSession], Awaitable[T]], *extra: str
) -> T:
    """``ask`` of a ``trace-audit mcp`` process over stdio, through the SDK's client."""
    args = ["-m", "trace_audit.cli", "mcp", *(a for r in roots for a in ("--root", str(r)))]
    params = StdioServerParameters(
        command=sys.executable,
        args=[*args, *extra],
        env={"PYTHONPATH": str(REPO), "PATH": os.environ.get("PATH", "")},
    )

    async def session() -> T:
        with anyio.fail_after(120):  # a hung server fails the test, never the suite
            async with stdio_client(params) as (read, write), ClientSession(read, write) as s:
                await s.initialize()
                return await ask(s)

    return anyio.run(session)


def _text(result: CallToolResult, n: int = 0) -> str:
    block = result.content[n]
    assert isinstance(block, TextContent)
    return block.text


def _cli_json(*args: str | Path) -> Any:
    done = cli(*args, "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_the_tools_are_listed_with_typed_schemas_and_find_only_with_an_index(root: Path) -> None:
    tools = _serve([root], lambda s: s.list_tools()).tools
    by_name = {t.name: t for t in tools}
    assert set(by_name) == {
        "robots", "why", "explain", "timeline", "metrics", "verify", "check", "prove",
    }  # fmt: skip
    why = by_name["why"]
    assert why.input_schema["required"] == ["log", "action"]
    assert "description" in why.input_schema["properties"]["t"]
    out = why.output_schema
    assert out is not None and list(out["properties"])[:2] == ["integrity", "reproduce"]
    assert "transitions" in json.dumps(out)  # the data is typed, not a bare object
    assert all(t.annotations and t.annotations.read_only_hint for t in tools)
    assert all(t.description and len(t.description) > 80 for t in tools)

    index = root.parent / "empty-index"
    index.mkdir(exist_ok=True)
    names = {t.name for t in _serve([root], lambda s: s.list_tools(), "--index", str(index)).tools}
    assert {"find", "query"} <= names


def test_why_on_a_sim_log_is_why_json_marked_verified(root: Path) -> None:
    async def ask(s: ClientSession) -> CallToolResult:
        return await s.call_tool("why", {"log": "sim", "action": _SIM_ACTION})

    result = _serve([root], ask)
    assert not result.is_error, _text(result)
    answer = result.structured_content
    assert answer is not None
    assert answer["data"] == _cli_json("why", root / "sim", "--action", _SIM_ACTION)
    assert answer["data"]["transitions"]  # the simulated robot did stop
    assert answer["integrity"]["status"] == "verified"
    assert answer["integrity"]["scope"]["cycles"] > 0
    assert _text(result).startswith("verified:")
    assert answer["reproduce"] == f"trace-audit why {root / 'sim'} --action STOP --json"
    assert answer["truncated"] == []


def test_a_tampered_copy_is_answered_with_integrity_failed_first(root: Path) -> None:
    before = snapshot(root)

    async def ask(s: ClientSession) -> list[CallToolResult]:
        args = {"log": str(root / "tampered"), "action": _SIM_ACTION}
        return [await s.call_tool("why", args), await s.call_tool("why", args)]

    first, again = _serve([root], ask)
    answer = first.structured_content
    assert answer is not None and not first.is_error
    assert list(answer)[0] == "integrity"
    assert answer["integrity"]["status"] == "integrity_failed"
    assert _text(first).startswith("integrity failed")
    assert answer["integrity"]["findings"][0]["kind"] == "modified"
    assert answer["integrity"]["findings_total"] >= 1
    assert answer["data"]["transitions"]  # still answered, under the warning
    assert again.structured_content is not None
    assert again.structured_content["integrity"]["scope"]["cached"] is True
    assert snapshot(root) == before  # nothing written


def test_paths_outside_the_roots_are_refused(root: Path, tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    segment = next((root / "sim" / "hot").glob("*.mcap"))
    (outside / "run.mcap").write_bytes(segment.read_bytes())
    inner = tmp_path / "inner"
    inner.mkdir()
    (inner / "escape").symlink_to(outside, target_is_directory=True)
    (inner / "run.mcap").symlink_to(outside / "run.mcap")
    os.mkfifo(inner / "pipe.mcap")

    async def ask(s: ClientSession) -> list[CallToolResult]:
        names = [str(outside / "run.mcap"), "escape", "escape/run.mcap", "run.mcap"]
        names += ["../outside/run.mcap", "pipe.mcap"]
        return [await s.call_tool("why", {"log": n, "action": "STOP"}) for n in names]

    results = _serve([inner], ask)
    for result in results:
        assert result.is_error
        assert "Traceback" not in _text(result)
    texts = [_text(r) for r in results]
    assert all("under the configured roots" in t for t in texts[:5]), texts
    assert "FIFO" in texts[5]


@pytest.mark.parametrize(
    ("tool", "args", "command"),
    [
        ("explain", {"cycle": 120}, ["explain", "--cycle", "120"]),
        ("timeline", {"start": "+2", "end": "+8"}, ["timeline", "--from", "+2", "--to", "+8"]),
        ("verify", {}, ["verify"]),
    ],
)
def test_each_answer_is_its_commands_json(
    root: Path, tool: str, args: dict[str, Any], command: list[str]
) -> None:
    async def ask(s: ClientSession) -> CallToolResult:
        return await s.call_tool(tool, {"log": "sim", **args})

    result = _serve([root], ask)
    assert not result.is_error, _text(result)
    assert result.structured_content is not None
    expected = _cli_json(command[0], root / "sim", *command[1:])
    assert result.structured_content["data"] == expected
