"""The assistant's tools: one per ``trace-audit`` command, arguments named like its options,
each answer typed (``answers.Answer``) and its description written for the model that
chooses which tool to call.

Each tool confines the paths it is given to the roots, says which command reproduces the
answer, and hands the question to the ``Assistant``; none writes anything.
"""

from __future__ import annotations

import inspect
import json
import shlex
from typing import Annotated, Any, Literal

from mcp.server.mcpserver.exceptions import ToolError
from mcp.server.mcpserver.tools import Tool
from mcp.types import CallToolResult, ToolAnnotations
from pydantic import BaseModel, Field

from trace_audit.assistant.answers import Answer
from trace_audit.assistant.arguments import CheckedTool
from trace_audit.assistant.server import Ask, Assistant, command_line
from trace_audit.info import LogInfo
from trace_audit.selection import PerRobot
from trace_audit.transitions import Timeline, WhyResult
from trace_runtime.verification.report import VerifyReport

__all__ = ["INSTRUCTIONS", "Tools", "tools_of"]

INSTRUCTIONS = """Tools to investigate TRACE robot decision logs (why a robot did something,
what it knew, whether the record can be trusted). Start with robots to see which logs and
robots the server can read. Every answer begins with its integrity: if the status is
integrity_failed, the log was changed or damaged after it was written; tell the user so
before anything else and do not present the data as fact. Times are in the log's own
clock (seconds, +seconds after the log start, or ISO 8601 on a wall clock). Each answer's
reproduce field is the trace-audit command that prints the same data."""

Log = Annotated[
    str,
    Field(
        description="The log: a path under one of the server's roots (robots lists them), "
        "relative to a root or absolute inside one; a segment file (.mcap), a folder of "
        "segments, or a log root (hot/ warm/ cold/). '.' is the first root."
    ),
]
Robots = Annotated[
    list[str] | None,
    Field(
        description='Only these robots, a list of names like ["amr-7"] (a root may hold '
        "several: robots lists them); the command's --robot, which repeats."
    ),
]
Time = Annotated[
    str | None,
    Field(
        description="A time in the log's clock: seconds (12.3), seconds after the log start "
        "(+12.3), or on a wall clock an ISO 8601 time (2026-05-04T06:04:25Z)."
    ),
]
Start = Annotated[str | None, Field(description="Start of the window (a time, as t).")]
End = Annotated[str | None, Field(description="End of the window (a time, as t).")]
Action = Annotated[str, Field(description="A command the robot logged, e.g. STOP (any case).")]


class RootHolding(BaseModel):
    """What one root holds: ``trace-audit info ROOT --quick --json``."""

    root: str = Field(description="The root's path.")
    info: LogInfo | PerRobot[LogInfo] | None = Field(
        description="Its log: robot(s), time range, cycles, segments and tiers (null: none)."
    )
    error: str | None = Field(None, description="Why the root has no readable log.")


_READ_ONLY = ToolAnnotations(readOnlyHint=True, destructiveHint=False, openWorldHint=False)


class Tools:
    """The tools, bound to one ``Assistant``; each method's docstring is its description."""

    def __init__(self, assistant: Assistant) -> None:
        self.a = assistant

    async def robots(self) -> Annotated[CallToolResult, Answer[list[RootHolding]]]:
        """What the server's roots hold: for each root its robots, time range, cycles,
        segments and tiers (no seal is read, so no integrity: ask verify about a log).
        Call this first to learn the log paths and robot names the other tools take."""
        roots = [str(p) for p in self.a.roots.paths]
        reproduce = " ; ".join(command_line("info", r, quick=True) for r in roots)
        return await self.a.answer(Ask("robots", {"roots": roots}, reproduce, "listing"))

    async def why(
        self, log: Log, action: Action, t: Time = None, robot: Robots = None
    ) -> Annotated[CallToolResult, Answer[WhyResult | PerRobot[WhyResult]]]:
        """Why did the robot take an action (e.g. why did it STOP)? Every transition into
        the action: when, what it changed from, how long it held, the logged rationale,
        the factors with their values (the leading one first), the counterfactuals and
        any execution flags. With t, only the transition in force at that time. Use it
        for "why did it stop / slow / reroute"."""
        path = self.a.log(log)
        args: dict[str, Any] = {"log": str(path), "action": action, "t": t, "robot": robot}
        reproduce = command_line("why", path, action=action, t=t, robot=robot)
        return await self.a.answer(Ask("why", args, reproduce, robots=robot or ()))

    async def explain(
        self,
        log: Log,
        t: Time = None,
        cycle: Annotated[int | None, Field(description="A cycle number instead of t.")] = None,
        robot: Robots = None,
    ) -> Annotated[CallToolResult, Answer[dict[str, Any]]]:
        """One decision in full, at time t (or cycle): the command and its alternatives
        with why each lost, the rationale, the factors and the chain from each factor
        back to the sensor evidence, counterfactuals, execution against intent, its
        scores (ET, DR, TCS) and whether its seal matches. Use it for "what exactly did it
        decide at t, and on what evidence"."""
        path = self.a.log(log)
        args: dict[str, Any] = {"log": str(path), "t": t, "cycle": cycle, "robot": robot}
        reproduce = command_line("explain", path, t=t, cycle=cycle, robot=robot)
        return await self.a.answer(Ask("explain", args, reproduce, robots=robot or ()))

    async def timeline(
        self,
        log: Log,
        start: Start = None,
        end: End = None,
        every: Annotated[bool, Field(description="A row per cycle, not per change.")] = False,
        robot: Robots = None,
    ) -> Annotated[CallToolResult, Answer[Timeline | PerRobot[Timeline]]]:
        """The decisions over time: a row per decision change (or per cycle with every)
        with the leading factor and flags, and the gaps where no cycle was logged. start
        and end are the command's --from and --to. Use it for "what happened between
        t1 and t2"."""
        path = self.a.log(log)
        args: dict[str, Any] = {
            "log": str(path),
            "start": start,
            "end": end,
            "every": every,
            "robot": robot,
        }
        options = {"from": start, "to": end, "every": every, "robot": robot}
        reproduce = command_line("timeline", path, **options)
        return await self.a.answer(Ask("timeline", args, reproduce, robots=robot or ()))

    async def metrics(
        self,
        *,
        log: Log,
        robot: Robots = None,
        by: Annotated[
            Literal["scenario", "segment", "robot", "hour"] | None,
            Field(description="A row of metrics per group."),
        ] = None,
        start: Start = None,
        end: End = None,
        failures: Annotated[
            bool, Field(description="List each decision that is not fully auditable.")
        ] = False,
    ) -> Annotated[CallToolResult, Answer[dict[str, Any]]]:
        """How auditable the log is: explanation traceability (ET, ET_partial), temporal
        continuity (TC, with gaps), decision reconstructability (DR) and the combined
        score (TCS), overall and per group. Use it for "can this log support an audit"."""
        path = self.a.log(log)
        args: dict[str, Any] = {
            "log": str(path),
            "robot": robot,
            "by": by,
            "start": start,
            "end": end,
        }
        args["failures"] = failures
        options = {"robot": robot, "by": by, "start": start, "end": end, "failures": failures}
        reproduce = command_line("metrics", path, **options)
        return await self.a.answer(Ask("metrics", args, reproduce, robots=robot or ()))

    async def verify(
        self, log: Log, robot: Robots = None
    ) -> Annotated[CallToolResult, Answer[VerifyReport]]:
        """Whether the log is intact: every cycle checked against its seal, the hash chain
        followed across segments (missing, inserted, reordered cycles), checkpoints
        recomputed; findings located by robot, segment and cycles. Use it when the user
        asks whether the record can be trusted, or before relying on a log."""
        path = self.a.log(log)
        reproduce = command_line("verify", path, robot=robot, **self.a.keys.options())
        args = {"log": str(path), "robot": robot, **self.a.keys.args()}
        ask = Ask("verify", args, reproduce, robots=robot or ())
        return await self.a.verify_answer(ask)

    async def check(
        self,
        log: Log,
        rules: Annotated[
            str,
            Field(
                description="The rules file (TOML: [[rule]] name, stl), a path under the "
                "server's roots like a log."
            ),
        ],
        robot: Robots = None,
        start: Start = None,
        end: End = None,
    ) -> Annotated[CallToolResult, Answer[dict[str, Any]]]:
        """Check STL safety rules (a rules file) over each robot's cycles: each rule
        satisfied, violated (with where and by how much) or not decidable. start and end
        are the command's --from and --to. Use it for "did the robot keep its rules"."""
        path, rules_path = self.a.log(log), self.a.file(rules, "rules file")
        args: dict[str, Any] = {"log": str(path), "rules": str(rules_path), "robot": robot}
        args |= {"start": start, "end": end}
        options = {"rules": rules_path, "robot": robot, "from": start, "to": end}
        reproduce = command_line("check", path, **options)
        return await self.a.answer(Ask("check", args, reproduce, robots=robot or ()))

    async def find(
        self,
        *,
        action: Annotated[str | None, Field(description="The command, e.g. STOP.")] = None,
        near: Annotated[
            str | None, Field(description="A perceived entity's class as logged, e.g. person.")
        ] = None,
        within: Annotated[
            float | None, Field(description="... closer than this many metres.")
        ] = None,
        where: Annotated[
            str | None, Field(description="An SQL condition on the decisions (alias d).")
        ] = None,
        robot: Robots = None,
        limit: Annotated[int, Field(ge=1, le=10_000, description="At most this many rows.")] = 100,
    ) -> Annotated[CallToolResult, Answer[list[dict[str, Any]]]]:
        """Find decisions across the fleet index (the server's --index): by command, by
        what the robot saw near it, by any SQL condition. Each row names its robot, time,
        segment and the explain command that reconstructs it. Use it for "when did any
        robot stop near a person"; then explain a row's decision from its log."""
        index = self.a.index_path()
        args: dict[str, Any] = {
            "index": str(index),
            "action": action,
            "near": near,
            "within": within,
        }
        args |= {"where": where, "robot": robot, "limit": limit}
        options = {"action": action, "near": near, "within": within, "where": where}
        reproduce = command_line("find", index, **options, robot=robot, limit=limit)
        return await self.a.answer(Ask("find", args, reproduce, "index"))

    async def query(
        self,
        sql: Annotated[
            str,
            Field(
                description="One read-only SQL statement over the index's tables "
                "(decisions, entities, gaps, ...)."
            ),
        ],
        limit: Annotated[int, Field(ge=0, le=10_000, description="At most this many rows.")] = 100,
    ) -> Annotated[CallToolResult, Answer[list[dict[str, Any]]]]:
        """Run one SQL statement (DuckDB) over the fleet index (the server's --index): for
        counts and aggregates across robots and days. Only the index's files are read;
        COPY, ATTACH, extensions and the network are refused."""
        index = self.a.index_path()
        reproduce = command_line("query", index, limit=limit)
        reproduce = reproduce.removesuffix(" --json") + " --json -- " + shlex.quote(sql)
        args = {"index": str(index), "sql": sql, "limit": limit}
        return await self.a.answer(Ask("query", args, reproduce, "index"))

    async def prove(
        self,
        log: Log,
        cycle: Annotated[int, Field(description="The cycle to prove.")],
        robot: Annotated[
            list[str] | None,
            Field(description="The robot, as a list of one name (needed on a root of several)."),
        ] = None,
    ) -> Annotated[CallToolResult, Answer[dict[str, Any]]]:
        """A proof bundle of one decision cycle, inline (nothing is written): its messages
        and seal, the seal's inclusion proof in the robot's Merkle tree and the signed
        checkpoint note, checkable without the log (trace-audit verify-proof). Use it when
        the user needs evidence of a decision to hand to someone else."""
        if robot is not None and len(robot) != 1:  # a list, as every tool's robot is
            given = json.dumps(robot)
            raise ToolError(f"prove proves one robot's cycle: give robot one name, not {given}")
        path = self.a.log(log)
        one = robot[0] if robot else None
        reproduce = command_line("prove", path, cycle=cycle, robot=one)
        reproduce = reproduce.removesuffix(" --json") + " --out BUNDLE.json"
        args: dict[str, Any] = {"log": str(path), "cycle": cycle, "robot": one}
        return await self.a.answer(Ask("prove", args, reproduce, robots=robot or ()))


def tools_of(assistant: Assistant) -> list[Tool]:
    """Every tool of the server; find and query only with an index."""
    tools = Tools(assistant)
    names = ["robots", "why", "explain", "timeline", "metrics", "verify", "check", "prove"]
    if assistant.index is not None:
        names += ["find", "query"]
    return [
        CheckedTool.of(method, name, _READ_ONLY, inspect.getdoc(method) or "")
        for name in names
        for method in [getattr(tools, name)]
    ]
