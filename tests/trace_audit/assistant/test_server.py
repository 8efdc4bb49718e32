"""``trace-audit mcp`` from the outside: a real server process, asked over stdio by the MCP
SDK's own client (``mcp.client.stdio`` + ``ClientSession``), as an assistant asks it."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import anyio
import pytest

from tests.outside import REPO, cli, one_line, snapshot
from tests.trace_audit.conftest import rewrite_segment

pytest.importorskip("mcp")

from mcp import ClientSession
from mcp.client.stdio import StdioServerParameters, stdio_client
from mcp.types import CallToolResult, TextContent

T = TypeVar("T")
_SIM_ACTION = "STOP"


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A root with a simulated robot's log (sim/, 100 cycles a scenario), a tampered
    copy of it (tampered/: one action message's rationale changed after it was sealed), a
    rules file, and a log with signed checkpoints (signed/: what a proof needs)."""
    from sim.runner import RunConfig, run
    from trace_runtime.tlog.keys import generate_keypair

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
    shutil.copy(REPO / "docs" / "rules" / "warehouse.toml", base / "rules.toml")
    key = generate_keypair(base.parent / "keys", name="amr-01").private_path
    run(RunConfig(out=base / "signed", scenario="all", cycles=40, seed=7, checkpoint_key=key))
    return base


def _serve(roots: list[Path], ask: Callable[[ClientSession], Awaitable[T]], *extra: str) -> T:
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
    assert next(iter(answer)) == "integrity"
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


_SAME_AS = [
    ("explain", {"cycle": 120}, ["explain", "--cycle", "120"]),
    ("timeline", {"start": "+2", "end": "+8"}, ["timeline", "--from", "+2", "--to", "+8"]),
    ("verify", {}, ["verify"]),
    ("metrics", {"by": "scenario"}, ["metrics", "--by", "scenario"]),
    ("check", {"rules": "rules.toml"}, ["check", "--rules", "{root}/rules.toml"]),
]
"""Tools, their arguments, and the command (after the log) that prints the same JSON."""


def test_each_answer_is_its_commands_json(root: Path) -> None:
    async def ask(s: ClientSession) -> list[CallToolResult]:
        return [await s.call_tool(tool, {"log": "sim", **args}) for tool, args, _ in _SAME_AS]

    for result, (tool, _, command) in zip(_serve([root], ask), _SAME_AS, strict=True):
        assert not result.is_error, (tool, _text(result))
        assert result.structured_content is not None
        assert result.structured_content["integrity"]["status"] == "verified", tool
        words = [w.replace("{root}", str(root)) for w in command[1:]]
        expected = _cli_json(command[0], root / "sim", *words)
        assert _unmeasured(result.structured_content["data"]) == _unmeasured(expected), tool


def _unmeasured(data: dict[str, Any]) -> dict[str, Any]:
    """The data without how fast this run was (metrics' elapsed_s, cycles_per_s)."""
    return {k: v for k, v in data.items() if k not in {"elapsed_s", "cycles_per_s"}}


def test_a_call_past_its_time_is_stopped_and_the_server_goes_on(root: Path) -> None:
    async def ask(s: ClientSession) -> list[CallToolResult]:
        first = await s.call_tool("verify", {"log": "sim"})
        return [first, await s.call_tool("why", {"log": "sim", "action": "STOP"})]

    # 0.05 s: less than a worker process needs to start, so every call overruns
    results = _serve([root], ask, "--timeout", "0.05")
    for result in results:
        assert result.is_error
        assert "did not finish within 0.05 s and was stopped" in _text(result)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--http", "0.0.0.0:8765"], "only a loopback address"),
        (["--http", "127.0.0.1"], "give 127.0.0.1:PORT"),
        (["--timeout", "0"], "--timeout must be above 0"),
    ],
)
def test_a_bad_option_is_one_line_and_exit_2(root: Path, args: list[str], needle: str) -> None:
    one_line(cli("mcp", "--root", root, *args), 2, needle)


def test_a_root_that_is_not_a_folder_is_one_line_and_exit_2(tmp_path: Path) -> None:
    one_line(cli("mcp", "--root", tmp_path / "nowhere"), 2, "not a folder")


def test_a_long_answer_is_cut_to_its_bound_and_says_so(root: Path) -> None:
    async def ask(s: ClientSession) -> CallToolResult:
        return await s.call_tool("timeline", {"log": "sim", "every": True})

    result = _serve([root], ask)
    answer = result.structured_content
    assert answer is not None and not result.is_error
    full = _cli_json("timeline", root / "sim", "--every")
    assert _size(full) > 200_000  # the premise: all of it would not fit
    assert _size(answer["data"]) <= 200_000
    [cut] = answer["truncated"]
    kept = answer["data"]["rows"]
    assert cut["path"] == "rows" and cut["robot"] is None
    assert (cut["kept"], cut["total"]) == (len(kept), len(full["rows"]))
    assert cut["through"] == f"cycle {kept[-1]['end_cycle']}, t {kept[-1]['end_t_ns'] / 1e9:g}"
    assert cut["rest"].startswith("ask timeline with a narrower window (start, end)")
    assert kept == full["rows"][: cut["kept"]]
    assert f"rows {cut['kept']} of {cut['total']}" in _text(result)


def _size(data: Any) -> int:
    """Bytes of ``data`` as compact JSON (what the bound counts)."""
    return len(json.dumps(data, separators=(",", ":"), ensure_ascii=False).encode())


def test_prove_answers_the_bundle_prove_writes_and_writes_nothing(
    root: Path, tmp_path: Path
) -> None:
    before = snapshot(root)

    async def ask(s: ClientSession) -> CallToolResult:
        return await s.call_tool("prove", {"log": "signed", "cycle": 50})

    result = _serve([root], ask)
    answer = result.structured_content
    assert answer is not None and not result.is_error, _text(result)
    assert snapshot(root) == before
    out = tmp_path / "bundle.json"
    done = cli("prove", root / "signed", "--cycle", "50", "--out", out)
    assert done.returncode == 0, done.stderr
    assert answer["data"] == json.loads(out.read_text())
    assert answer["integrity"]["status"] == "verified"
    assert answer["reproduce"].endswith("--cycle 50 --out BUNDLE.json")


def test_find_and_query_answer_from_the_index_marked_unverified(root: Path) -> None:
    index = root.parent / "index"
    built = cli("index", root / "sim", "--out", index)
    assert built.returncode == 0, built.stderr
    sql = "SELECT command, count(*) AS n FROM decisions GROUP BY ALL ORDER BY command"

    async def ask(s: ClientSession) -> list[CallToolResult]:
        return [
            await s.call_tool("find", {"action": "STOP", "limit": 5}),
            await s.call_tool("query", {"sql": sql}),
        ]

    found, queried = _serve([root], ask, "--index", str(index))
    for result in (found, queried):
        assert not result.is_error, _text(result)
        assert result.structured_content is not None
        assert result.structured_content["integrity"]["status"] == "unverified"
        assert _text(result).startswith("unverified: answered from the fleet index")
    assert found.structured_content is not None and queried.structured_content is not None
    rows = found.structured_content["data"]
    assert rows and rows == _cli_json("find", index, "--action", "STOP", "--limit", "5")
    assert queried.structured_content["data"] == _cli_json("query", index, "--limit", "100", sql)


def test_streamable_http_on_loopback_answers_the_same(root: Path) -> None:
    from mcp.client.streamable_http import streamable_http_client

    with socket.socket() as probe:  # a free port, given back for the server to take
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    command = ["-m", "trace_audit.cli", "mcp", "--root", str(root), "--http", f"127.0.0.1:{port}"]
    server = subprocess.Popen(
        [sys.executable, *command],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )

    async def ask() -> CallToolResult:
        with anyio.fail_after(120):
            while True:  # until the server listens
                try:
                    await (await anyio.connect_tcp("127.0.0.1", port)).aclose()
                    break
                except OSError:
                    assert server.poll() is None, "the server exited"
                    await anyio.sleep(0.2)
            url = f"http://127.0.0.1:{port}/mcp"
            async with (
                streamable_http_client(url) as (read, write),
                ClientSession(read, write) as s,
            ):
                await s.initialize()
                return await s.call_tool("why", {"log": "sim", "action": _SIM_ACTION})

    try:
        result = anyio.run(ask)
    finally:
        server.terminate()
        _, err = server.communicate(timeout=30)  # and closes its pipes
    assert b"Traceback" not in err, err
    assert result.structured_content is not None
    assert result.structured_content["integrity"]["status"] == "verified"
    assert result.structured_content["data"]["transitions"]
