"""One segment's rows of the fleet index, built from the decisions metrics scored.

``SegmentRows`` is a ``trace_audit.metrics.DecisionSink``: metrics reads the segment and
scores each decision once (ET, ET_partial, DR, the seal check, the gap rule); this module
only copies those figures and the parsed layers' fields into columns. Nothing here scores.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from trace_audit.metrics import NO_SCENARIO, ScoredDecision, scenario_of
from trace_runtime.reader import Segment

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["SegmentRows", "day_of"]

_HOUR_NS = 3_600_000_000_000
_DISTANCE_UNITS = ("m", "meter", "metre", "meters", "metres")


def day_of(t_ns: int) -> str:
    """The UTC day of a log time, ``YYYY-MM-DD`` (the index's partition value)."""
    return time.strftime("%Y-%m-%d", time.gmtime(t_ns // 1_000_000_000))


def _number(value: Any) -> float | None:
    kind = type(value)
    if kind is float:
        return value  # type: ignore[no-any-return]
    if kind is int or kind is bool:
        return float(value)
    return None


def _distances(belief: Any) -> dict[str, float]:
    """Entity id -> distance to the robot, where the belief graph derives one: a state node
    labelled or named ``distance`` in metres with a documented edge from the entity."""
    if type(belief) is not dict:
        return {}
    values: dict[Any, float] = {}
    for node in belief.get("nodes") or ():
        if (
            type(node) is dict
            and node.get("unit") in _DISTANCE_UNITS
            and node.get("kind") == "state"
            and "distance" in f"{node.get('label', '')} {node.get('id', '')}".lower()
        ):
            value = _number(node.get("value"))
            if value is not None:
                values[node.get("id")] = value
    if not values:
        return {}
    out: dict[str, float] = {}
    for edge in belief.get("edges") or ():
        if type(edge) is dict:
            value = values.get(edge.get("child"))
            if value is not None:
                parent = str(edge.get("parent"))
                out[parent] = min(value, out.get(parent, value))
    return out


@dataclass(slots=True)
class SegmentRows:
    """The decisions, entities and gaps of one segment, filled decision by decision.

    Rows are kept as tuples in the tables' column order (one tuple per row is the cheapest
    thing to build per decision) and turned into columns once, in ``table``."""

    segment: Segment
    previous_command: str | None = None
    rows: dict[str, list[tuple[Any, ...]]] = field(default_factory=dict)
    days: dict[str, list[str]] = field(default_factory=dict)
    integrity_failed: int = 0
    first_cycle: int | None = None
    last_cycle: int | None = None
    _hours: dict[int, tuple[str, str]] = field(default_factory=dict)
    _name: str = ""
    _path: str = ""

    def __post_init__(self) -> None:
        for table in ("decisions", "entities", "gaps"):
            self.rows[table] = []
            self.days[table] = []
        self._name = self.segment.path.name
        self._path = str(self.segment.path)

    @property
    def decisions(self) -> int:
        return len(self.rows["decisions"])

    def _day_hour(self, t_ns: int) -> tuple[str, str]:
        bucket = t_ns // _HOUR_NS
        found = self._hours.get(bucket)
        if found is None:
            t = time.gmtime(t_ns // 1_000_000_000)
            found = self._hours[bucket] = (
                time.strftime("%Y-%m-%d", t),
                time.strftime("%Y-%m-%d %H:00", t),
            )
        return found

    def __call__(self, d: ScoredDecision) -> None:
        """Add one scored decision (the ``DecisionSink`` protocol)."""
        cycle = d.cycle
        day, hour = self._day_hour(cycle.t_ns)
        if self.first_cycle is None:
            self.first_cycle = cycle.cycle
        self.last_cycle = cycle.cycle
        perception = d.perception
        nearest: dict[str, float] = {}
        if type(perception) is dict and perception.get("entities"):
            nearest = self._entities(d, perception["entities"], day)
        self._decision(d, day, hour, nearest)
        if d.seal.gap is not None:
            self._gap(d, self._day_hour(d.seal.gap.after_t_ns)[0])

    def _decision(self, d: ScoredDecision, day: str, hour: str, nearest: dict[str, float]) -> None:
        self.days["decisions"].append(day)
        action = d.action if type(d.action) is dict else {}
        execution = d.execution if type(d.execution) is dict else {}
        rationale = action.get("rationale")
        raw_factors = rationale.get("factors") if type(rationale) is dict else None
        factors = []
        for f in raw_factors or ():
            if type(f) is dict:
                raw = f.get("value")
                value = _number(raw)
                factors.append(
                    {
                        "node": str(f.get("node", "")),
                        "name": str(f.get("name", "")),
                        "value": value,
                        "text": None if value is not None else str(raw),
                        "unit": f.get("unit"),
                    }
                )
        lead = factors[0] if factors else None
        command = action.get("command")
        session = self.segment.session
        score, seal = d.score, d.seal
        scenario = scenario_of(execution)
        intact = not seal.problems
        self.integrity_failed += not intact
        gap = seal.gap
        self.rows["decisions"].append(
            (
                self._name,
                self._path,
                session.tier,
                d.cycle.cycle,
                d.cycle.t_ns,
                hour,
                command,
                self.previous_command,
                (lead["name"] or lead["node"]) if lead else None,
                lead["value"] if lead else None,
                lead["text"] if lead else None,
                lead["unit"] if lead else None,
                factors,
                len(action.get("alternatives") or ()),
                len(action.get("counterfactuals") or ()),
                _number(execution.get("deviation")),
                [
                    str(c.get("rule"))
                    for c in execution.get("checks") or ()
                    if type(c) is dict and c.get("passed") is False
                ],
                [str(f) for f in execution.get("flags") or ()],
                list(nearest.items()),
                None if scenario == NO_SCENARIO else scenario,
                score.et,
                score.et_partial,
                score.factors,
                score.traceable,
                not d.dr_problems,
                list(d.dr_problems),
                seal.sealed,
                intact,
                list(seal.problems),
                d.cycle.summary is not None,
                seal.continuity,
                d.tcs,
                seal.window_ns,
                gap.gap_ns if gap is not None else 0,
                gap.missing_cycles if gap is not None else 0,
                seal.dropped,
                seal.clock_anomaly,
                session.software_version,
                session.policy_version,
            )
        )
        if command is not None:
            self.previous_command = str(command)

    def _gap(self, d: ScoredDecision, day: str) -> None:
        gap = d.seal.gap
        assert gap is not None  # the caller checked
        self.days["gaps"].append(day)
        self.rows["gaps"].append(
            (
                self._name,
                gap.after_cycle,
                gap.after_t_ns,
                gap.before_cycle,
                gap.before_t_ns,
                gap.period_ns,
                gap.gap_ns,
                gap.missing_cycles,
                gap.declared_dropped,
            )
        )

    def _entities(self, d: ScoredDecision, entities: Any, day: str) -> dict[str, float]:
        """Add the cycle's entity rows; return the nearest distance of each class seen."""
        distances = _distances(d.belief)
        nearest: dict[str, float] = {}
        rows = self.rows["entities"]
        days = self.days["entities"]
        name, number, t_ns = self._name, d.cycle.cycle, d.cycle.t_ns
        for entity in entities:
            if type(entity) is not dict:
                continue
            cls = entity.get("class")
            confidence = entity.get("confidence")
            pose = entity.get("pose")
            position = pose.get("position") if type(pose) is dict else None
            xy = position if type(position) is list and len(position) >= 2 else (None, None)
            entity_id = str(entity.get("id", ""))
            distance = distances.get(entity_id)
            if distance is not None and cls is not None:
                key = str(cls)
                nearest[key] = min(distance, nearest.get(key, distance))
            days.append(day)
            rows.append(
                (
                    name,
                    number,
                    t_ns,
                    entity_id,
                    None if cls is None else str(cls),
                    _number(confidence.get(cls)) if type(confidence) is dict else None,
                    distance,
                    _number(xy[0]),
                    _number(xy[1]),
                    len(entity.get("evidence") or ()),
                )
            )
        return nearest

    def table(self, name: str) -> tuple[pa.Table, list[str]]:
        """One table's rows as Arrow, and the partition day of each row."""
        import pyarrow as pa

        from trace_audit.fleet.tables import schema

        shape = schema(name)
        rows = self.rows[name]
        columns = list(zip(*rows, strict=True)) if rows else [()] * len(shape)
        arrays = [pa.array(column, type=f.type) for column, f in zip(columns, shape, strict=True)]
        return pa.Table.from_arrays(arrays, schema=shape), self.days[name]
