"""``trace-audit mcp`` on a root of two robots, asked by the SDK's own client over stdio
(found from outside): a long answer is cut evenly across the robots, each cut saying which
robot's and how to ask for the rest; ``robot`` is a list in every tool; a bad argument is
one line naming it and what it takes; an unknown argument is refused, not ignored."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from tests.outside import cli
from tests.trace_audit.assistant.test_server import _serve, _text

pytest.importorskip("mcp")

from mcp import ClientSession
from mcp.types import CallToolResult

_BOUND = 200_000


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A root whose fleet/ holds two simulated robots with signed checkpoints, amr-1 (700
    cycles) and amr-2 (400): a timeline of every cycle of both is about 600 KB."""
    from sim.runner import RunConfig, run
    from trace_runtime.tlog.keys import generate_keypair

    base = tmp_path_factory.mktemp("mcp-fleet")
    key = generate_keypair(base / "keys", name="fleet").private_path
    for robot, cycles, seed in (("amr-1", 700, 1), ("amr-2", 400, 2)):
        config = RunConfig(
            out=base / "root" / "fleet", total_cycles=cycles, seed=seed, robot_id=robot,
            checkpoint_key=key,
        )  # fmt: skip
        run(config)
    return base / "root"


def _calls(root: Path, calls: list[tuple[str, dict[str, Any]]]) -> list[CallToolResult]:
    async def ask(s: ClientSession) -> list[CallToolResult]:
        return [await s.call_tool(name, args) for name, args in calls]

    return _serve([root], ask)


def test_a_long_answer_about_two_robots_is_cut_evenly_and_says_so_per_robot(root: Path) -> None:
    [result] = _calls(root, [("timeline", {"log": "fleet", "every": True})])
    answer = result.structured_content
    assert answer is not None and not result.is_error, _text(result)
    done = cli("timeline", root / "fleet", "--every", "--json")
    full = {r["robot"]: r["rows"] for r in json.loads(done.stdout)["robots"]}
    assert len(done.stdout) > 2 * _BOUND  # the premise: all of it would not fit
    assert len(json.dumps(answer["data"], separators=(",", ":"))) <= _BOUND
    kept = {r["robot"]: r["rows"] for r in answer["data"]["robots"]}
    assert kept["amr-1"] == full["amr-1"][: len(kept["amr-1"])]  # the first rows, in order
    assert kept["amr-2"] == full["amr-2"][: len(kept["amr-2"])]
    sizes = sorted(len(rows) for rows in kept.values())
    assert sizes[0] > 0.85 * sizes[1], sizes  # even, not 1 row for one and hundreds for the other
    cuts = {c["robot"]: c for c in answer["truncated"]}
    assert set(cuts) == {"amr-1", "amr-2"}
    for robot, cut in cuts.items():
        assert (cut["kept"], cut["total"]) == (len(kept[robot]), len(full[robot]))
        last = kept[robot][-1]
        assert cut["through"] == f"cycle {last['end_cycle']}, t {last['end_t_ns'] / 1e9:g}"
        assert cut["rest"].startswith(f'ask timeline with robot ["{robot}"] and a narrower window')
    lead = _text(result).splitlines()[2]
    for robot, cut in cuts.items():
        assert f"{robot} rows {cut['kept']} of {cut['total']} (through {cut['through']})" in lead
    assert lead.endswith("for the rest: ask about one robot at a time (each cut's rest in "
                         "truncated says how)")  # fmt: skip


def test_robot_is_a_list_in_every_tool_and_no_tool_takes_other_arguments(root: Path) -> None:
    async def ask(s: ClientSession) -> Any:
        return await s.list_tools()

    tools = _serve([root], ask).tools
    for tool in tools:
        assert tool.input_schema.get("additionalProperties") is False, tool.name
        robot = tool.input_schema["properties"].get("robot")
        if robot is not None:
            assert {"type": "array", "items": {"type": "string"}} in robot["anyOf"], tool.name
    assert {t.name for t in tools if "robot" in t.input_schema["properties"]} >= {
        "why", "explain", "timeline", "metrics", "verify", "check", "prove",
    }  # fmt: skip


_REFUSED = [
    ("why", {"log": "fleet", "action": "STOP", "robot": "amr-1"},
     'argument robot takes a list of strings or null, not "amr-1"'),
    ("why", {"log": "fleet"}, "argument action is missing (required: log, action)"),
    ("explain", {"log": "fleet", "cycle": "x"}, 'argument cycle takes an integer or null, not "x"'),
    ("metrics", {"log": "fleet", "by": "day"},
     'argument by takes one of "scenario", "segment", "robot", "hour" or null, not "day"'),
    ("why", {"log": "fleet", "action": "STOP", "bogus": 1, "robots": ["amr-1"]},
     "unknown arguments bogus, robots: why takes log, action, t, robot"),
    ("verify", {"log": "fleet", "key": "x"}, "unknown argument key: verify takes log, robot"),
    ("prove", {"log": "fleet", "cycle": 3, "robot": ["amr-1", "amr-2"]},
     'prove proves one robot\'s cycle: give robot one name, not ["amr-1", "amr-2"]'),
    ("prove", {"log": "fleet", "cycle": 3},
     "the log holds 2 robots (amr-1, amr-2): name one with --robot"),
]  # fmt: skip
"""Calls refused, and what their one line says after ``Error executing tool NAME: ``."""


def test_a_refused_call_is_one_line_naming_the_argument(root: Path) -> None:
    results = _calls(root, [(name, args) for name, args, _ in _REFUSED])
    for result, (name, _, said) in zip(results, _REFUSED, strict=True):
        assert result.is_error, (name, _text(result))
        assert [c.type for c in result.content] == ["text"]
        assert _text(result) == f"Error executing tool {name}: {said}"


def test_prove_takes_its_robot_as_a_list_of_one(root: Path, tmp_path: Path) -> None:
    [result] = _calls(root, [("prove", {"log": "fleet", "cycle": 30, "robot": ["amr-2"]})])
    answer = result.structured_content
    assert answer is not None and not result.is_error, _text(result)
    assert answer["reproduce"].endswith("--cycle 30 --robot amr-2 --out BUNDLE.json")
    out = tmp_path / "b.json"
    done = cli("prove", root / "fleet", "--cycle", "30", "--robot", "amr-2", "--out", out)
    assert done.returncode == 0, done.stderr
    assert answer["data"] == json.loads(out.read_text())
