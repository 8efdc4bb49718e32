"""Checking rules over a fleet index: each robot's rows of the index as signals, judged by
the same evaluator as a log's cycles (``rules.judge``).

The index's tables (docs/fleet.md) are read with DuckDB, one robot at a time, its rows in
time order within each clock run (the ``day`` partition: a UTC day on a wall clock, which
orders as the times do, ``run-<segment>`` otherwise): ``decisions`` for the command, the
factors, the nearest distance per class and the flags; ``channels`` and ``checks`` for the
signals of those families; ``gaps`` for the gaps, never interpolated, as on the logs; a
planar robot's linear motion (``channel.speed.*`` when no channel is named ``speed``)
comes from ``decisions.intended_linear`` and ``actual_linear`` by the logs' own rule
(``signals.planar_speed``).

The SQL runs through a query function the caller gives (``query(sql, params) -> columns``),
the fleet package's bounded, confined ``ColumnSession`` (``trace_audit.fleet``, which stands
on a floor above this one): nothing here opens a file. Given an ``Executor`` (a Dask
cluster's, ``--scheduler``), each robot is one task (its rows read and judged on a worker,
so the query function must pickle); the answers are kept in robot order, as locally.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from typing import NamedTuple, TypeGuard

import numpy as np
from numpy.typing import NDArray

from trace_audit.log_time import LogClock
from trace_audit.rules.formula import RulesError
from trace_audit.rules.judge import Labels, RobotSignals, judge
from trace_audit.rules.results import CheckResult, GroupRules, RobotRules
from trace_audit.rules.rulebook import Rule
from trace_audit.rules.signals import command_signal, planar_speed
from trace_runtime.errors import UsageError
from trace_runtime.gaps import Gap

__all__ = [
    "BY_KEYS",
    "NOT_WALL_CLOCK",
    "IndexColumns",
    "IndexQuery",
    "check_index",
    "judge_index_robot",
]

IndexColumns = Mapping[str, NDArray[np.generic]]
"""A statement's result as numpy columns by name (of the column's SQL type; NULL as NaN in
numbers and None in text)."""

IndexQuery = Callable[[str, Sequence[object]], IndexColumns]
"""Runs one SQL statement with parameters on the index; its result as columns
(``trace_audit.fleet.ColumnSession``)."""

Cell = str | int | float | bool | None
"""A value of a small result's row (``_rows``): a number, a text, a flag or NULL."""

BY_KEYS = ("robot", "day")
"""What ``check --index --by`` groups by."""

NOT_WALL_CLOCK = "not a wall clock (the index does not name it)"
"""The clock name of a robot whose index rows are under ``run-`` partitions: its times are
shown as seconds, as on a sim or monotonic log."""

_RUN_ORDER = "CASE WHEN starts_with(day, 'run-') THEN day ELSE '' END"
"""Clock runs in chain order; wall-clock days all in one, ordered by time."""


def check_index(
    query: IndexQuery,
    rules: Sequence[Rule],
    *,
    robots: Sequence[str] = (),
    by: Sequence[str] = (),
    index: str = "",
    rules_file: str = "",
    executor: Executor | None = None,
    engine: str = "auto",
) -> CheckResult:
    """Every rule over each selected robot of the index ``query`` reads; with ``by`` naming
    ``day``, also per robot and day (``CheckResult.groups``). ``executor``: one task a
    robot on it (None: one after the other here). ``engine`` as ``check_rules``'."""
    if not rules:
        raise RulesError(f"{rules_file or 'the rules'}: no rules to check")
    _refuse_log_only_signals(rules, rules_file)
    for key in by:
        if key not in BY_KEYS:
            raise UsageError(f"cannot group rules by {key!r} (use {', '.join(BY_KEYS)})")
    held = [
        str(r) for r in query("SELECT DISTINCT robot FROM segments ORDER BY robot", [])["robot"]
    ]
    wanted = list(dict.fromkeys(robots)) or held
    missing = [repr(r) for r in wanted if r not in held]
    if missing:
        holds = ", ".join(held) if held else "no robot"
        raise UsageError(f"robot {', '.join(missing)} is not in this index; it holds {holds}")
    by_day = "day" in by
    if executor is None:
        judged = [judge_index_robot(query, robot, tuple(rules), by_day, engine) for robot in wanted]
    else:
        tasks = [
            executor.submit(judge_index_robot, query, robot, tuple(rules), by_day, engine)
            for robot in wanted
        ]
        judged = [task.result() for task in tasks]
    answers = tuple(answer for answer, _ in judged)
    groups = tuple(group for _, robot_groups in judged for group in robot_groups)
    return CheckResult(index, rules_file, answers, groups)


LOG_ONLY_FAMILIES = ("perception", "evidence")
"""Signal families the fleet index does not hold (sensor lists, the age of cited readings):
read from the logs only."""


def _refuse_log_only_signals(rules: Sequence[Rule], rules_file: str) -> None:
    """A rule reading a signal the index does not hold is refused (exit 2), never judged
    "not decidable" on every row as if the robot had not logged it."""
    for rule in rules:
        for name in rule.formula.signals:
            if name.partition(".")[0] in LOG_ONLY_FAMILIES:
                raise RulesError(
                    f"{rules_file or 'the rules'}: rule {rule.name!r}: {name} is read from the "
                    "logs, not the fleet index: check the logs (trace-audit check LOG|ROOT --rules)"
                )


def judge_index_robot(
    query: IndexQuery, robot: str, rules: tuple[Rule, ...], by_day: bool, engine: str = "auto"
) -> tuple[RobotRules, tuple[GroupRules, ...]]:
    """One robot of the index judged (and, ``by_day``, per day): one task of a fan-out."""
    signals = robot_signals(query, robot, rules)
    return judge(signals, rules, by_group=by_day, engine=engine)


def robot_signals(query: IndexQuery, robot: str, rules: Sequence[Rule]) -> RobotSignals:
    """One robot's rows of the index, in time order, with the signals ``rules`` read."""
    names = tuple(dict.fromkeys(s for rule in rules for s in rule.formula.signals))
    paths, period_ns, clock = _segments(query, robot)
    channels, logged = _channels(query, robot, names)
    planar = "speed" not in logged and any(n.startswith("channel.speed.") for n in names)
    checks = _checks(query, robot, names)
    texts = {
        column: [
            str(v)
            for v in query(
                f"SELECT DISTINCT {column} AS v FROM decisions WHERE robot = ? ORDER BY v",
                [robot],
            )["v"].tolist()
            if v is not None
        ]
        for column in ("segment", "command", "day")
    }
    exprs, params = _decision_columns(names, planar)
    data = query(
        f"SELECT {', '.join(exprs)}, "
        + ", ".join(f"coalesce(list_position(?::VARCHAR[], d.{c}), 0) AS {c}_code" for c in texts)
        + f" FROM decisions d LEFT JOIN ({_GAPS}) g "
        "ON g.segment = d.segment AND g.before_cycle = d.cycle AND g.before_t_ns = d.t_ns "
        f"WHERE d.robot = ? ORDER BY {_RUN_ORDER}, d.t_ns, d.cycle",
        [*params, *texts.values(), robot, robot],
    )
    labels = {  # code 0: NULL (a command not logged)
        c: Labels(np.asarray(data[f"{c}_code"], dtype=np.int64), (None, *names_))
        for c, names_ in texts.items()
    }
    n = len(data["cycle"])
    cycles = np.asarray(data["cycle"], dtype=np.int64)
    t_ns = np.asarray(data["t_ns"], dtype=np.int64)
    segment = labels["segment"]
    by_row = _RowValues(data, labels, (segment, cycles, t_ns), n, channels, checks, planar)
    return RobotSignals(
        robot,
        period_ns,
        clock,
        cycles,
        t_ns,
        labels["command"],
        {name: value for name in names if (value := by_row.signal(name)) is not None},
        np.ones(n, dtype=np.bool_),
        Labels(segment.codes, tuple(s and paths.get(s, s) for s in segment.names)),
        _gaps(robot, data),
        labels["day"],
    )


def _segments(query: IndexQuery, robot: str) -> tuple[dict[str, str], int, LogClock]:
    """The robot's segments in the index: each one's path by name, the cycle period rules
    are judged at (``RulesError`` when none is declared), and the clock its times are shown
    on (a wall clock unless every row is under a ``run-`` partition)."""
    segments = _rows(
        query(
            "SELECT segment, segment_path, period_ns, start_ns, day FROM segments WHERE robot = ?",
            [robot],
        )
    )
    paths = {str(s[0]): str(s[1]) for s in segments}
    period_ns = max((int(s[2]) for s in segments if _present(s[2])), default=0)
    if period_ns <= 0:
        raise RulesError(f"{robot}: the index declares no cycle period to judge rules at")
    start_ns = min((int(s[3]) for s in segments if _present(s[3])), default=0)
    wall = any(not str(s[4]).startswith("run-") for s in segments)
    return paths, period_ns, LogClock("system" if wall else NOT_WALL_CLOCK, start_ns)


class _RowValues(NamedTuple):
    """What a signal's value at each decision row is read from: the decision columns, the
    text columns as codes, the rows' keys (segment, cycle, t_ns), and the channel and check
    values by key."""

    data: IndexColumns
    labels: Mapping[str, Labels]
    keys: tuple[Labels, NDArray[np.int64], NDArray[np.int64]]
    n: int
    channels: Mapping[tuple[str, int, int, str], float]
    checks: Mapping[tuple[str, int, int, str], float]
    planar: bool

    def signal(self, name: str) -> NDArray[np.float64] | None:
        """The signal ``name`` at each row; None for a family the index does not hold."""
        family, _, rest = name.partition(".")
        if family == "command":
            return _indicator(self.labels["command"], rest)
        if family in ("nearest", "flag"):
            return np.asarray(self.data[name], dtype=np.float64)
        if family == "factor":
            return _factor_values(self.data["factors"], rest)
        if self.planar and name.startswith("channel.speed."):
            part = name.removeprefix("channel.speed.")
            return _planar(part, self.data["intended_linear"], self.data["actual_linear"])
        if family == "channel":
            return _by_key(self.channels, self.keys, name, self.n)
        if family == "check":
            return _by_key(self.checks, self.keys, name, self.n)
        return None


_GAPS = (
    "SELECT DISTINCT ON (segment, before_cycle, before_t_ns) segment, after_cycle, "
    "after_t_ns, before_cycle, before_t_ns, period_ns, gap_ns, missing_cycles, "
    "declared_dropped FROM gaps WHERE robot = ?"
)
"""The robot's gaps, one for the row after each (segment, cycle, t_ns)."""


def _rows(columns: IndexColumns) -> list[tuple[Cell, ...]]:
    """A small result's columns as rows."""
    return list(zip(*(c.tolist() for c in columns.values()), strict=True))


def _present(value: object) -> TypeGuard[int | float]:
    """Whether a number column's value is there (NULL reads as NaN, or None)."""
    return value is not None and not (isinstance(value, float) and math.isnan(value))


def _int(value: Cell) -> int:
    """``int(value)`` of a whole-number column the index never leaves NULL (``cycle``,
    ``t_ns``); a NULL fails as ``int(None)`` would."""
    if value is None:
        raise TypeError("a NULL in a column of whole numbers the index always fills")
    return int(value)


def _decision_columns(names: Sequence[str], planar: bool) -> tuple[list[str], list[str]]:
    """What to select from ``decisions`` (``d``, its gap joined as ``g``) and the SQL's
    parameters: the row's place, its command, each ``nearest.<class>`` as the class's value
    in the ``nearest`` map (+inf when the class is not in it) and each ``flag.<name>`` as
    whether ``flags`` holds it (0/1), both taken out by DuckDB under the signal's name; the
    factors whole (a factor is found by node or name); ``planar``: the linear motion too;
    the gap before the row (NULL ``after_cycle``: none)."""
    exprs = ["d.cycle", "d.t_ns"]
    params: list[str] = []
    for name in names:
        family, _, rest = name.partition(".")
        if family == "nearest":
            sql = "coalesce(map_extract(d.nearest, ?)[1], 'inf'::DOUBLE)"
        elif family == "flag":
            sql = "coalesce(list_contains(d.flags, ?), false)::DOUBLE"
        else:
            continue
        exprs.append(f'{sql} AS "{name}"')
        params.append(rest)
    if any(n.startswith("factor.") for n in names):
        exprs.append("d.factors")
    if planar:
        exprs += ["d.intended_linear", "d.actual_linear"]
    exprs += [f"g.{c} AS gap_{c}" for c in _GAP_COLUMNS]
    return exprs, params


_GAP_COLUMNS = (
    "after_cycle",
    "after_t_ns",
    "period_ns",
    "gap_ns",
    "missing_cycles",
    "declared_dropped",
)


def _indicator(commands: Labels, action: str) -> NDArray[np.float64]:
    """``command.<action>`` at each row (NaN: no command logged), by ``command_signal``."""
    per_code = [command_signal(c, action) for c in commands.names]
    table = np.array([np.nan if v is None else v for v in per_code], dtype=np.float64)
    return table[commands.codes]


def _planar(
    part: str, intended: NDArray[np.generic], actual: NDArray[np.generic]
) -> NDArray[np.float64]:
    """``channel.speed.<part>`` at each row, by ``planar_speed`` over the columns."""
    i = np.asarray(intended, dtype=np.float64)
    a = np.asarray(actual, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.asarray(planar_speed(part, i, a), dtype=np.float64)


def _factor_values(factors: NDArray[np.generic], wanted: str) -> NDArray[np.float64]:
    out = np.full(len(factors), np.nan)
    for row, items in enumerate(factors.tolist()):
        for factor in () if items is None else items:  # a list, or DuckDB's array of them
            if wanted in (factor.get("node"), factor.get("name")):
                value = factor.get("value")
                if value is not None:
                    out[row] = float(value)
                break
    return out


def _by_key(
    found: Mapping[tuple[str, int, int, str], float],
    keys: tuple[Labels, NDArray[np.int64], NDArray[np.int64]],
    name: str,
    n: int,
) -> NDArray[np.float64]:
    """A channel or check signal at each row, from its values by (segment, cycle, t_ns)."""
    out = np.full(n, np.nan)
    if not found:
        return out
    segments, codes = keys[0].names, keys[0].codes.tolist()
    cycles, t_ns = keys[1].tolist(), keys[2].tolist()
    for row in range(n):
        value = found.get((str(segments[codes[row]]), cycles[row], t_ns[row], name))
        if value is not None:
            out[row] = value
    return out


def _gaps(robot: str, data: IndexColumns) -> dict[int, Gap]:
    """Row -> the gap that ends before it, from the joined ``gap_*`` columns."""
    after = data["gap_after_cycle"]
    rows = np.flatnonzero(~np.isnan(np.asarray(after, dtype=np.float64)))
    out: dict[int, Gap] = {}
    for row in rows.tolist():
        dropped = data["gap_declared_dropped"][row]
        out[row] = Gap(
            robot,
            int(after[row]),
            int(data["gap_after_t_ns"][row]),
            int(data["cycle"][row]),
            int(data["t_ns"][row]),
            int(data["gap_period_ns"][row]),
            int(data["gap_gap_ns"][row]),
            int(data["gap_missing_cycles"][row]),
            None if not _present(dropped) else int(dropped),
        )
    return out


def _channels(
    query: IndexQuery, robot: str, names: Sequence[str]
) -> tuple[dict[tuple[str, int, int, str], float], set[str]]:
    """(segment, cycle, t_ns, signal) -> value, for the channel signals named; and the
    channels among them the robot logs at all."""
    wanted: dict[str, list[tuple[str, str]]] = {}
    for n in names:
        if n.startswith("channel."):
            name, _, part = n.removeprefix("channel.").rpartition(".")
            wanted.setdefault(name, []).append((part, n))
    if not wanted:
        return {}, set()
    marks = ", ".join("?" for _ in wanted)
    out: dict[tuple[str, int, int, str], float] = {}
    logged: set[str] = set()
    for segment, cycle, t_ns, channel, intended, actual, deviation in _rows(
        query(
            "SELECT segment, cycle, t_ns, channel, intended, actual, deviation FROM channels "
            f"WHERE robot = ? AND channel IN ({marks})",
            [robot, *wanted],
        )
    ):
        logged.add(str(channel))
        parts = {"intended": intended, "actual": actual, "deviation": deviation}
        for part, n in wanted[str(channel)]:
            key = (str(segment), _int(cycle), _int(t_ns), n)
            value = parts[part]
            if key not in out and _present(value):  # the first such channel, as logged
                out[key] = float(value)
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
    for segment, cycle, t_ns, rule, passed in _rows(
        query(
            "SELECT segment, cycle, t_ns, rule, passed FROM checks "
            f"WHERE robot = ? AND rule IN ({marks})",
            [robot, *wanted],
        )
    ):
        key = (str(segment), _int(cycle), _int(t_ns), wanted[str(rule)])
        out[key] = min(out.get(key, 1.0), 1.0 if passed is True else 0.0)
    return out
