"""Whole layers of a log as Arrow tables, and its decisions as typed objects, for notebooks.

Each function takes a log (a path or an open ``Log``) and the same selection every command
uses (``trace_audit.selection``): ``robots`` (none: all of the log's) and a window
``start``/``end`` (int ns in the log's clock, or text as the CLI reads it: ``12.3``, ``+5``,
an ISO 8601 time on a wall clock). Rows run robot by robot (robots in order of name), each
robot's in time order, and every row names its robot.

- ``iter_decisions`` yields each cycle's ``Decision`` (``read_decision``, what the CLI renders);
  ``iter_decision_fields`` only what each decision chose and why, decoded from its action
  message alone (``trace_runtime.encoding.partial.DecisionFields``), for walking long logs.
- ``decision_table``, ``channel_table`` and ``check_table`` are columns of those decisions;
  ``entity_table`` the perceived entities; ``gap_table`` the gaps between sealed cycles by the
  one gap rule (``trace_runtime.gaps``). Columns are the fleet index's where it has the
  same column (one definition of each, ``trace_audit.columns``; docs/fleet.md);
  ``.to_pandas()`` gives a DataFrame.

pyarrow comes with the ``fleet`` extra; without it the tables raise ``UsageError``.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, NamedTuple, TypedDict

from trace_audit.causal import (
    Decision,
    FactorValue,
    format_value,
    layer_with_defaults,
    read_decision,
)
from trace_audit.causal.lenient import (
    as_float,
    as_mapping,
    as_number_or_flag,
    as_str,
    mappings,
)
from trace_audit.columns import (
    DECISION_WHY,
    channel_columns,
    check_columns,
    decision_columns,
    entity_columns,
    gap_columns,
    gap_row,
)
from trace_audit.log_gaps import gap_stepper
from trace_audit.log_source import LogSource, as_log
from trace_audit.log_time import TimeArg
from trace_audit.selection import Selection, each_robot
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.partial import DecisionFields, decision_fields
from trace_runtime.encoding.seal_check import verify_cycle
from trace_runtime.errors import UsageError
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE, check_tolerance
from trace_runtime.reading.logset import Log
from trace_runtime.records import TOPIC_PERCEPTION, Scalar

if TYPE_CHECKING:  # the fleet extra, imported when a table is built (``_pyarrow``)
    import pyarrow

__all__ = [
    "RobotDecision",
    "RobotDecisionFields",
    "channel_table",
    "check_table",
    "decision_table",
    "entity_table",
    "gap_table",
    "iter_decision_fields",
    "iter_decisions",
]

Robots = str | Sequence[str]
"""One robot's id, or several (empty: every robot of the log)."""


class RobotDecision(NamedTuple):
    """One logged decision and the robot that made it."""

    robot: str
    decision: Decision


class RobotDecisionFields(NamedTuple):
    """One decision's own fields, its segment and the robot that made it."""

    robot: str
    segment: str
    fields: DecisionFields


def iter_decisions(
    source: LogSource, *, robots: Robots = (), start: TimeArg = None, end: TimeArg = None
) -> Iterator[RobotDecision]:
    """Every decision of the selected robots in the window, as the CLI reads it (the
    selection is checked here, before the first decision is read)."""
    cycles = _iter_selected(source, robots, start, end)
    return (RobotDecision(robot, read_decision(cycle)) for robot, cycle in cycles)


def iter_decision_fields(
    source: LogSource, *, robots: Robots = (), start: TimeArg = None, end: TimeArg = None
) -> Iterator[RobotDecisionFields]:
    """What each decision of the selected robots chose and why (``DecisionFields``: the
    command, score, rationale, factors, and how many alternatives and counterfactuals),
    decoded from its action message alone: no other layer, no tree, no ``Decision``. The
    fast way to walk a long log's decisions (``iter_decisions`` builds every record of
    each). Cycles without an action message are left out."""
    for robot, cycle in _iter_selected(source, robots, start, end):
        fields = decision_fields(cycle)
        if fields is not None:
            yield RobotDecisionFields(robot, cycle.segment, fields)


def decision_table(
    source: LogSource, *, robots: Robots = (), start: TimeArg = None, end: TimeArg = None
) -> pyarrow.Table:
    """A ``pyarrow.Table`` with one row per decision: what it did, why, and its seal."""
    pa = _pyarrow()
    rows = _Columns(pa, _decision_schema(pa))
    for robot, cycle in _iter_selected(source, robots, start, end):
        decision = read_decision(cycle, with_tree=False)  # no column holds the tree
        execution = decision.execution
        lead = decision.leading
        seal = verify_cycle(cycle)
        rows.add(
            robot,
            decision.segment,
            decision.cycle,
            decision.t_ns,
            decision.command,
            decision.score,
            decision.rationale,
            decision.truncated,
            lead.label if lead else None,
            as_number_or_flag(lead.value) if lead else None,
            _text(lead.value) if lead else None,
            lead.unit if lead else None,
            [_factor(f) for f in decision.factors],
            len(decision.alternatives),
            len(decision.counterfactuals),
            execution.deviation if execution else None,
            execution.deviation_unit if execution else None,
            [c.rule for c in execution.checks if not c.passed] if execution else [],
            list(execution.flags) if execution else [],
            execution.scenario if execution else None,
            decision.summary,
            cycle.sealed,
            seal.ok,
        )
    return rows.table()


def entity_table(
    source: LogSource, *, robots: Robots = (), start: TimeArg = None, end: TimeArg = None
) -> pyarrow.Table:
    """A ``pyarrow.Table`` with one row per perceived entity of each decision.

    ``x``, ``y``, ``z`` and ``frame`` are the entity's logged position (null where the record
    has none: nothing assumes a planar robot); ``confidence`` is that of its own class."""
    pa = _pyarrow()
    rows = _Columns(pa, _entity_schema(pa))
    for robot, cycle in _iter_selected(source, robots, start, end):
        perception = as_mapping(layer_with_defaults(cycle, TOPIC_PERCEPTION))
        for entity in mappings(perception.get("entities") if perception else None):
            cls = as_str(entity.get("class"))
            confidence = as_mapping(entity.get("confidence"))
            pose = as_mapping(entity.get("pose"))
            x, y, z = _position(pose.get("position") if pose else None)
            rows.add(
                robot,
                cycle.cycle,
                cycle.t_ns,
                as_str(entity.get("id")),
                cls,
                as_float(confidence.get(cls)) if confidence and cls else None,
                x,
                y,
                z,
                as_str(pose.get("frame")) if pose else None,
                len(list(mappings(entity.get("evidence")))),
            )
    return rows.table()


def channel_table(
    source: LogSource, *, robots: Robots = (), start: TimeArg = None, end: TimeArg = None
) -> pyarrow.Table:
    """A ``pyarrow.Table`` with one row per logged actuator channel of each decision
    (profile 1.1): intended, actual and deviation in the channel's ``unit``; ``deviation_unit``
    is the unit of the execution record's overall deviation."""
    pa = _pyarrow()
    rows = _Columns(pa, _channel_schema(pa))
    for robot, decision in iter_decisions(source, robots=robots, start=start, end=end):
        execution = decision.execution
        for channel in execution.channels if execution else ():
            rows.add(
                robot,
                decision.cycle,
                decision.t_ns,
                channel.name,
                channel.intended,
                channel.actual,
                channel.deviation,
                channel.unit,
                execution.deviation_unit if execution else None,
            )
    return rows.table()


def check_table(
    source: LogSource, *, robots: Robots = (), start: TimeArg = None, end: TimeArg = None
) -> pyarrow.Table:
    """A ``pyarrow.Table`` with one row per compliance check of each decision's execution."""
    pa = _pyarrow()
    rows = _Columns(pa, _check_schema(pa))
    for robot, decision in iter_decisions(source, robots=robots, start=start, end=end):
        execution = decision.execution
        for check in execution.checks if execution else ():
            rows.add(
                robot,
                decision.cycle,
                decision.t_ns,
                check.rule,
                check.passed,
                check.value,
                check.limit,
                check.detail,
            )
    return rows.table()


def gap_table(
    source: LogSource,
    *,
    robots: Robots = (),
    start: TimeArg = None,
    end: TimeArg = None,
    tolerance: float = DEFAULT_GAP_TOLERANCE,
) -> pyarrow.Table:
    """A ``pyarrow.Table`` with one row per gap between two sealed cycles of a robot inside
    the window (``trace_runtime.gaps``: ``gap_ns`` is the time beyond one period)."""
    pa = _pyarrow()
    check_tolerance(tolerance)
    rows = _Columns(pa, _gap_schema(pa))
    log, lo, hi = _selected(source, robots, start, end)
    for robot_log in each_robot(log):
        step = gap_stepper(robot_log, tolerance)
        for cycle in robot_log.iter_cycles(lo, hi):
            gap = step(cycle)
            if gap is not None:
                rows.add(*gap_row(gap.robot, gap))
    return rows.table()


# --- selection -----------------------------------------------------------------------------


def _selected(
    source: LogSource, robots: Robots, start: TimeArg, end: TimeArg
) -> tuple[Log, int | None, int | None]:
    """The log cut to the robots, and the window in its clock (``Selection``)."""
    chosen = (robots,) if isinstance(robots, str) else tuple(robots)
    selection = Selection(chosen, start, end)
    log = selection.of(as_log(source))
    lo, hi = selection.window(log)
    return log, lo, hi


def _iter_selected(
    source: LogSource, robots: Robots, start: TimeArg, end: TimeArg
) -> Iterator[tuple[str, Cycle]]:
    """Each selected robot's cycles in the window: robots by name, each in time order. The
    log is opened and the selection checked now; the cycles are read as they are asked for."""
    log, lo, hi = _selected(source, robots, start, end)
    return ((r.first_robot, cycle) for r in each_robot(log) for cycle in r.iter_cycles(lo, hi))


# --- columns -------------------------------------------------------------------------------


def _pyarrow() -> ModuleType:
    # import_module says what it returns (a module); a plain import of the untyped package
    # would be Any to mypy.
    try:
        return importlib.import_module("pyarrow")
    except ImportError as err:
        raise UsageError("the layer tables need pyarrow: pip install 'trace-audit[fleet]'") from err


class _Columns:
    """Rows gathered column by column, made into one table at the end."""

    def __init__(self, pa: ModuleType, schema: pyarrow.Schema) -> None:
        self.pa, self.schema = pa, schema
        # A cell is whatever pyarrow converts to its column's type (str, int, float, bool,
        # None, lists of those, a factor's dict): the schema, not Python, types it.
        self.values: list[list[object]] = [[] for _ in schema.names]

    def add(self, *row: object) -> None:
        for column, value in zip(self.values, row, strict=True):
            column.append(value)

    def table(self) -> pyarrow.Table:
        pa, schema = self.pa, self.schema
        return pa.Table.from_arrays(
            [pa.array(v, type=f.type) for v, f in zip(self.values, schema, strict=True)],
            schema=schema,
        )


def _text(value: Scalar | None) -> str | None:
    """A factor's value as text when it is not a number (the CLI's rendering)."""
    return None if value is None or as_number_or_flag(value) is not None else format_value(value)


class _FactorCell(TypedDict):
    """A factor in the ``factors`` column (``trace_audit.columns.factor_struct``)."""

    node: str
    name: str
    value: float | None
    text: str | None
    unit: str | None


def _factor(factor: FactorValue) -> _FactorCell:
    return {
        "node": factor.node,
        "name": factor.name,
        "value": as_number_or_flag(factor.value),
        "text": _text(factor.value),
        "unit": factor.unit,
    }


def _position(value: object) -> tuple[float | None, float | None, float | None]:
    """x, y, z of a logged position (a list of numbers); None for what is not there."""
    if not isinstance(value, list):
        return None, None, None
    x, y, z = ([as_float(v) for v in value[:3]] + [None, None, None])[:3]
    return x, y, z


_DECISION_COLUMNS = (
    "robot",
    "segment",
    "cycle",
    "t_ns",
    "command",
    "score",
    "rationale",
    "truncated",
    *DECISION_WHY,
    "failed_checks",
    "flags",
    "scenario",
    "summarized",
    "sealed",
    "seal_verified",
)
_ENTITY_COLUMNS = (
    "robot",
    "cycle",
    "t_ns",
    "entity",
    "class",
    "confidence",
    "x",
    "y",
    "z",
    "frame",
    "evidence",
)


def _decision_schema(pa: ModuleType) -> pyarrow.Schema:
    return pa.schema(decision_columns(pa, _DECISION_COLUMNS))


def _entity_schema(pa: ModuleType) -> pyarrow.Schema:
    return pa.schema(entity_columns(pa, _ENTITY_COLUMNS))


def _channel_schema(pa: ModuleType) -> pyarrow.Schema:
    return pa.schema([("robot", pa.string()), *channel_columns(pa)])


def _check_schema(pa: ModuleType) -> pyarrow.Schema:
    return pa.schema([("robot", pa.string()), *check_columns(pa)])


def _gap_schema(pa: ModuleType) -> pyarrow.Schema:
    return pa.schema([("robot", pa.string()), *gap_columns(pa)])
