"""``find``: the named question over the fleet index, decisions by command, by a perceived
entity's class and distance, by robot and by any SQL condition, each with the exact
``trace-audit explain`` command that reconstructs it (``decisions.explain``)."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from trace_audit.fleet.limits import QueryLimits
from trace_audit.fleet.query import QueryResult, run_query, sql_literal
from trace_runtime.errors import UsageError

__all__ = ["FoundRun", "find_decisions", "found_runs", "index_robots"]

log = logging.getLogger("trace_audit")

_COLUMNS = (
    "d.robot, d.day, d.t_ns, d.cycle, d.command, d.previous_command, d.lead_factor, "
    "d.lead_value, d.lead_unit, d.et, d.dr, d.seal_verified, d.software_version"
)
"""The columns a found decision shows, before the nearest entity's and ``explain``."""


def find_decisions(
    index: str | Path,
    *,
    action: str | None = None,
    near: str | None = None,
    within_m: float | None = None,
    where: str | None = None,
    robots: Sequence[str] = (),
    limit: int = 1000,
    limits: QueryLimits | None = None,
) -> QueryResult:
    """Decisions by command, by a perceived entity's class and distance, and by any SQL
    condition on the decisions' columns; each row with ``robot``, ``t_ns`` and ``explain``.

    ``robots``: only these robots' decisions (none: every robot's); a robot the index
    does not hold is a ``UsageError`` naming those it does (``index_robots``)."""
    conditions: list[str] = []
    params: list[Any] = []
    if action is not None:
        conditions.append("upper(d.command) = upper(?)")
        params.append(action)
    if robots:
        robots = _held_robots(index, robots, limits)
        # One placeholder per robot: the ids themselves only ever travel as parameters.
        conditions.append(f"d.robot IN ({', '.join('?' for _ in robots)})")
        params.extend(robots)
    if where:
        conditions.append(f"({where})")
    select = _COLUMNS
    if near is not None or within_m is not None:
        nearest, within = _nearest(near, within_m)
        select += nearest
        conditions += within
    sql = f"SELECT {select}, d.explain FROM decisions d"
    if conditions:
        sql += " WHERE " + " AND ".join(conditions)
    try:
        ordered = sql + f" ORDER BY d.t_ns, d.robot LIMIT {int(limit)}"
        found = run_query(index, ordered, params, limits=limits)
    except UsageError as err:
        if where:  # the error is about SQL the user did not write around the condition
            raise UsageError(f"--where {where!r}: {err}") from err
        raise
    if near is not None and not found.rows:
        _say_why_none_is_near(index, near, limits)
    if len(found.rows) < limit:
        return found
    # As many rows as the limit: count the matches so the output can say it was cut.
    count = run_query(index, f"SELECT count(*) FROM ({sql})", params, limits=limits).rows[0][0]
    assert isinstance(count, int)  # count(*) is a BIGINT, never NULL
    return dataclasses.replace(found, total=int(count) if count > len(found.rows) else None)


@dataclass(frozen=True, slots=True)
class FoundRun:
    """Found decisions of one robot in a row: consecutive cycles holding one command (a
    stop held for 2 s is 20 found cycles, one run). What a person reads of ``find``; the
    rows themselves (one per cycle) are what scripts read."""

    robot: str
    command: str | None
    previous_command: str | None
    """The command before the run's first cycle."""
    first_cycle: int
    last_cycle: int
    first_ns: int
    last_ns: int
    decisions: int
    wall: bool
    """The robot's clock tells the time of day (the index's ``day`` is a UTC date)."""
    first: dict[str, object]
    """The run's first row, by column (its lead factor, its ``explain`` command)."""
    nearest_m: float | None
    """The closest the nearest entity came over the run (with ``--near``/``--within``)."""
    et_lowest: float | None
    """The lowest ET over the run; None when any is unknown or none was scored."""


def found_runs(result: QueryResult) -> list[FoundRun]:
    """``find_decisions``' rows grouped into runs, in time order: a row continues its
    robot's run when it holds the same command at the next cycle number."""
    runs: list[FoundRun] = []
    open_runs: dict[str, int] = {}  # robot -> index of its run still open in ``runs``
    for row in result.records():
        robot, cycle = str(row["robot"]), int(row["cycle"])  # type: ignore[call-overload]
        at = open_runs.get(robot)
        run = runs[at] if at is not None else None
        if run is not None and run.command == row["command"] and cycle == run.last_cycle + 1:
            runs[at] = _extended(run, row)  # type: ignore[index]
            continue
        open_runs[robot] = len(runs)
        runs.append(_started(row))
    return runs


def _started(row: dict[str, object]) -> FoundRun:
    t_ns, cycle = int(row["t_ns"]), int(row["cycle"])  # type: ignore[call-overload]
    et = row.get("et")
    return FoundRun(
        robot=str(row["robot"]),
        command=None if row["command"] is None else str(row["command"]),
        previous_command=None if row["previous_command"] is None else str(row["previous_command"]),
        first_cycle=cycle,
        last_cycle=cycle,
        first_ns=t_ns,
        last_ns=t_ns,
        decisions=1,
        wall=not str(row["day"]).startswith("run-"),
        first=row,
        nearest_m=_number(row.get("nearest_m")),
        et_lowest=_number(et),
    )


def _extended(run: FoundRun, row: dict[str, object]) -> FoundRun:
    near, et = _number(row.get("nearest_m")), _number(row.get("et"))
    return dataclasses.replace(
        run,
        last_cycle=int(row["cycle"]),  # type: ignore[call-overload]
        last_ns=int(row["t_ns"]),  # type: ignore[call-overload]
        decisions=run.decisions + 1,
        nearest_m=near
        if run.nearest_m is None or (near is not None and near < run.nearest_m)
        else run.nearest_m,
        et_lowest=None if run.et_lowest is None or et is None else min(run.et_lowest, et),
    )


def _number(value: object) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


def _nearest(near: str | None, within_m: float | None) -> tuple[str, list[str]]:
    """The columns naming the nearest entity (of class ``near``, else of any class) and
    its distance, and the conditions that it exists and, with ``within_m``, is closer.

    From the decision's own ``nearest`` map (class -> nearest distance), built from the
    same entity rows: one scan of one table, no join of two fleet-sized ones."""
    if near is not None:
        distance = f"d.nearest[{sql_literal(near)}]"
        select = f", {sql_literal(near)} AS nearest_class"
    else:
        distance = "list_min(map_values(d.nearest))"
        select = (
            ", map_keys(d.nearest)[list_position(map_values(d.nearest), "
            f"{distance})] AS nearest_class"
        )
    select += f", {distance} AS nearest_m"
    conditions = [f"{distance} IS NOT NULL"]
    if within_m is not None:
        if not math.isfinite(within_m):
            raise UsageError(f"--within must be a finite distance, got {within_m}")
        conditions.append(f"{distance} < {float(within_m)!r}")
    return select, conditions


def _say_why_none_is_near(index: str | Path, near: str, limits: QueryLimits | None) -> None:
    """No decision has a ``near`` entity at a known distance: when the index does hold such
    entities, say that their distance is what is missing, not the entities."""
    sql = "SELECT count(*), count(distance) FROM entities WHERE class = ?"
    seen, measured = run_query(index, sql, [near], limits=limits).rows[0]
    if isinstance(seen, int) and seen and not measured:
        log.warning(
            "%d %s entit(ies) are indexed, none at a known distance: a distance comes from a "
            "belief state node of a distance unit whose parent is the entity (docs/fleet.md)",
            seen,
            near,
        )


def index_robots(index: str | Path, limits: QueryLimits | None = None) -> list[str]:
    """The robots the index holds (those with an indexed segment), sorted."""
    found = run_query(index, "SELECT DISTINCT robot FROM segments ORDER BY robot", limits=limits)
    return [str(row[0]) for row in found.rows]


def _held_robots(index: str | Path, robots: Sequence[str], limits: QueryLimits | None) -> list[str]:
    """``robots`` once each; ``UsageError`` naming the index's robots when one is not held."""
    wanted = list(dict.fromkeys(robots))
    held = index_robots(index, limits)
    missing = [repr(r) for r in wanted if r not in held]
    if missing:
        holds = ", ".join(held) if held else "no robot"
        raise UsageError(f"robot {', '.join(missing)} is not in this index; it holds {holds}")
    return wanted
