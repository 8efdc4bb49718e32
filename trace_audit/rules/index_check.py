"""Checking rules over a fleet index: each robot's rows of the index as signals, judged by
the same evaluator as a log's cycles (``rules.judge``).

The index's tables (docs/fleet.md) are read with DuckDB, one robot at a time, its rows in
time order within each clock run (the ``day`` partition: a UTC day on a wall clock, which
orders as the times do, ``run-<segment>`` otherwise): ``decisions`` for the command, the
factors, the nearest distance per class and the flags; ``channels`` and ``checks`` for the
signals of those families; ``gaps`` for the gaps, never interpolated, as on the logs. What
a planar robot's linear motion (``channel.speed.*`` when no channel is named ``speed``)
comes from ``decisions.intended_linear`` and ``actual_linear`` by the logs' own rule
(``signals.planar_speed``).

The SQL runs through a query function the caller gives (``query(sql, params) -> rows``),
the fleet package's bounded, confined ``run_query`` (``trace_audit.fleet``, which stands on
a floor above this one): nothing here opens a file. Given an ``Executor`` (a Dask
cluster's, ``--scheduler``), each robot is one task (its rows read and judged on a worker,
so the query function must pickle); the answers are kept in robot order, as locally.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from typing import Any

from trace_audit.log_time import LogClock
from trace_audit.rules.formula import RulesError
from trace_audit.rules.judge import RobotSignals, SignalRow, judge_groups, judge_robot
from trace_audit.rules.results import CheckResult, GroupRules, RobotRules
from trace_audit.rules.rulebook import Rule
from trace_audit.rules.signals import command_signal, planar_speed
from trace_runtime.errors import UsageError
from trace_runtime.gaps import Gap

__all__ = ["BY_KEYS", "NOT_WALL_CLOCK", "IndexQuery", "check_index", "judge_index_robot"]

IndexQuery = Callable[[str, Sequence[Any]], Sequence[Sequence[Any]]]
"""Runs one SQL statement with parameters on the index; the rows."""

BY_KEYS = ("robot", "day")
"""What ``check --index --by`` groups by."""

NOT_WALL_CLOCK = "not a wall clock (the index does not name it)"
"""The clock name of a robot whose index rows are under ``run-`` partitions: its times are
shown as seconds, as on a sim or monotonic log."""

_RUN_ORDER = "CASE WHEN starts_with(day, 'run-') THEN day ELSE '' END"
"""Clock runs in chain order; wall-clock days all in one, ordered by time."""

Key = tuple[str, int, int]
"""A row's place: (segment, cycle, t_ns)."""


def check_index(
    query: IndexQuery,
    rules: Sequence[Rule],
    *,
    robots: Sequence[str] = (),
    by: Sequence[str] = (),
    index: str = "",
    rules_file: str = "",
    executor: Executor | None = None,
) -> CheckResult:
    """Every rule over each selected robot of the index ``query`` reads; with ``by`` naming
    ``day``, also per robot and day (``CheckResult.groups``). ``executor``: one task a
    robot on it (None: one after the other here)."""
    if not rules:
        raise RulesError(f"{rules_file or 'the rules'}: no rules to check")
    for key in by:
        if key not in BY_KEYS:
            raise UsageError(f"cannot group rules by {key!r} (use {', '.join(BY_KEYS)})")
    held = [str(row[0]) for row in query("SELECT DISTINCT robot FROM segments ORDER BY robot", [])]
    wanted = list(dict.fromkeys(robots)) or held
    missing = [repr(r) for r in wanted if r not in held]
    if missing:
        holds = ", ".join(held) if held else "no robot"
        raise UsageError(f"robot {', '.join(missing)} is not in this index; it holds {holds}")
    by_day = "day" in by
    if executor is None:
        judged = [judge_index_robot(query, robot, tuple(rules), by_day) for robot in wanted]
    else:
        tasks = [
            executor.submit(judge_index_robot, query, robot, tuple(rules), by_day)
            for robot in wanted
        ]
        judged = [task.result() for task in tasks]
    answers = tuple(answer for answer, _ in judged)
    groups = tuple(group for _, robot_groups in judged for group in robot_groups)
    return CheckResult(index, rules_file, answers, groups)


def judge_index_robot(
    query: IndexQuery, robot: str, rules: tuple[Rule, ...], by_day: bool
) -> tuple[RobotRules, tuple[GroupRules, ...]]:
    """One robot of the index judged (and, ``by_day``, per day): one task of a fan-out."""
    signals = robot_signals(query, robot, rules)
    return judge_robot(signals, rules), judge_groups(signals, rules) if by_day else ()


def robot_signals(query: IndexQuery, robot: str, rules: Sequence[Rule]) -> RobotSignals:
    """One robot's rows of the index, in time order, with the signals ``rules`` read."""
    names = tuple(dict.fromkeys(s for rule in rules for s in rule.formula.signals))
    segments = query(
        "SELECT segment, segment_path, period_ns, start_ns, day FROM segments WHERE robot = ?",
        [robot],
    )
    paths = {str(s[0]): str(s[1]) for s in segments}
    period_ns = max((int(s[2] or 0) for s in segments), default=0)
    if period_ns <= 0:
        raise RulesError(f"{robot}: the index declares no cycle period to judge rules at")
    start_ns = min((int(s[3]) for s in segments if s[3] is not None), default=0)
    wall = any(not str(s[4]).startswith("run-") for s in segments)
    clock = LogClock("system" if wall else NOT_WALL_CLOCK, start_ns)
    channels, logged = _channels(query, robot, names)
    planar = "speed" not in logged and any(n.startswith("channel.speed.") for n in names)
    checks = _checks(query, robot, names)
    gaps = _gaps(query, robot)
    columns, exprs, params = _decision_columns(names, planar)
    rows: list[SignalRow] = []
    for values in query(
        f"SELECT {', '.join(exprs)} FROM decisions WHERE robot = ? "
        f"ORDER BY {_RUN_ORDER}, t_ns, cycle",
        [*params, robot],
    ):
        row = dict(zip(columns, values, strict=True))
        segment, cycle, t_ns = str(row["segment"]), int(row["cycle"]), int(row["t_ns"])
        key = (segment, cycle, t_ns)
        command = row["command"]
        signals: dict[str, float] = {}
        for name in names:
            channel = channels.get((*key, name))
            if planar and name.startswith("channel.speed."):
                channel = planar_speed(
                    name.removeprefix("channel.speed."),
                    row["intended_linear"],
                    row["actual_linear"],
                )
            value = _signal(name, row, channel, checks.get((*key, name)))
            if value is not None:
                signals[name] = value
        rows.append(
            SignalRow(
                cycle,
                t_ns,
                None if command is None else str(command),
                signals,
                gaps.get(key),
                True,
                paths.get(segment, segment),
                str(row["day"]),
            )
        )
    return RobotSignals(robot, period_ns, clock, rows)


def _decision_columns(names: Sequence[str], planar: bool) -> tuple[list[str], list[str], list[Any]]:
    """What to select from ``decisions``: the names the row's values go by, their SQL, and
    its parameters. A ``nearest.<class>`` is the class's value in the row's ``nearest`` map
    (+inf when the class is not in it) and a ``flag.<name>`` whether ``flags`` holds it, both
    taken out by DuckDB; the factors come whole (a factor is found by node or name);
    ``planar``: the linear motion too."""
    columns = ["day", "segment", "cycle", "t_ns", "command"]
    exprs = list(columns)
    params: list[Any] = []
    for name in names:
        family, _, rest = name.partition(".")
        if family == "nearest":
            exprs.append("coalesce(map_extract(nearest, ?)[1], 'inf'::DOUBLE)")
        elif family == "flag":
            exprs.append("coalesce(list_contains(flags, ?), false)")
        else:
            continue
        columns.append(name)
        params.append(rest)
    if any(n.startswith("factor.") for n in names):
        columns.append("factors")
        exprs.append("factors")
    if planar:
        columns += ["intended_linear", "actual_linear"]
        exprs += ["intended_linear", "actual_linear"]
    return columns, exprs, params


def _signal(
    name: str, row: dict[str, Any], channel: float | None, check: float | None
) -> float | None:
    """One signal's value on one decision row (None: the row does not hold it)."""
    family, _, rest = name.partition(".")
    if family == "command":
        command = row["command"]
        return command_signal(None if command is None else str(command), rest)
    if family == "nearest":
        return float(row[name])
    if family == "factor":
        for factor in row["factors"] or ():
            if rest in (factor.get("node"), factor.get("name")):
                value = factor.get("value")
                return None if value is None else float(value)
        return None
    if family == "flag":
        return 1.0 if row[name] else 0.0
    if family == "check":
        return check
    if family == "channel":
        return channel
    return None


def _channels(
    query: IndexQuery, robot: str, names: Sequence[str]
) -> tuple[dict[tuple[str, int, int, str], float], set[str]]:
    """(segment, cycle, t_ns, signal) -> value, for the channel signals named; and the
    channels among them the robot logs at all."""
    wanted: dict[str, list[tuple[str, str]]] = {}
    for n in names:
        if n.startswith("channel."):
            channel, _, part = n.removeprefix("channel.").rpartition(".")
            wanted.setdefault(channel, []).append((part, n))
    if not wanted:
        return {}, set()
    marks = ", ".join("?" for _ in wanted)
    out: dict[tuple[str, int, int, str], float] = {}
    logged: set[str] = set()
    for segment, cycle, t_ns, channel, intended, actual, deviation in query(
        "SELECT segment, cycle, t_ns, channel, intended, actual, deviation FROM channels "
        f"WHERE robot = ? AND channel IN ({marks})",
        [robot, *wanted],
    ):
        logged.add(str(channel))
        parts = {"intended": intended, "actual": actual, "deviation": deviation}
        for part, n in wanted[str(channel)]:
            key = (str(segment), int(cycle), int(t_ns), n)
            if key not in out and parts[part] is not None:  # the first such channel, as logged
                out[key] = float(parts[part])
    return out, logged


def _checks(
    query: IndexQuery, robot: str, names: Sequence[str]
) -> dict[tuple[str, int, int, str], float]:
    """(segment, cycle, t_ns, signal) -> 1.0 when every check of that rule passed, else 0.0."""
    wanted = {n.removeprefix("check."): n for n in names if n.startswith("check.")}
    if not wanted:
        return {}
    marks = ", ".join("?" for _ in wanted)
    out: dict[tuple[str, int, int, str], float] = {}
    for segment, cycle, t_ns, rule, passed in query(
        "SELECT segment, cycle, t_ns, rule, passed FROM checks "
        f"WHERE robot = ? AND rule IN ({marks})",
        [robot, *wanted],
    ):
        key = (str(segment), int(cycle), int(t_ns), wanted[str(rule)])
        out[key] = min(out.get(key, 1.0), 1.0 if passed is True else 0.0)
    return out


def _gaps(query: IndexQuery, robot: str) -> dict[Key, Gap]:
    """The robot's gaps by the row after each: (segment, cycle, t_ns)."""
    out: dict[Key, Gap] = {}
    for row in query(
        "SELECT segment, after_cycle, after_t_ns, before_cycle, before_t_ns, period_ns, gap_ns, "
        "missing_cycles, declared_dropped FROM gaps WHERE robot = ?",
        [robot],
    ):
        after_cycle, after_t, before_cycle, before_t, period, gap_ns, missing = map(int, row[1:8])
        dropped = None if row[8] is None else int(row[8])
        gap = Gap(
            robot, after_cycle, after_t, before_cycle, before_t, period, gap_ns, missing, dropped
        )
        segment = row[0]
        out[(str(segment), gap.before_cycle, gap.before_t_ns)] = gap
    return out
