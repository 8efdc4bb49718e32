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
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, int | float):
        return float(value)
    return None


def _distances(belief: Any) -> dict[str, float]:
    """Entity id -> distance to the robot, where the belief graph derives one: a state node
    labelled or named ``distance`` in metres with a documented edge from the entity."""
    if not isinstance(belief, dict):
        return {}
    nodes = {
        n.get("id"): n
        for n in belief.get("nodes") or ()
        if isinstance(n, dict) and n.get("kind") == "state" and n.get("unit") in _DISTANCE_UNITS
    }
    out: dict[str, float] = {}
    for edge in belief.get("edges") or ():
        if not isinstance(edge, dict):
            continue
        node = nodes.get(edge.get("child"))
        if node is None:
            continue
        name = f"{node.get('label', '')} {node.get('id', '')}".lower()
        value = _number(node.get("value"))
        if "distance" in name and value is not None:
            parent = str(edge.get("parent"))
            out[parent] = min(value, out.get(parent, value))
    return out


@dataclass(slots=True)
class SegmentRows:
    """Columns of the decisions, entities and gaps of one segment, filled decision by decision."""

    segment: Segment
    previous_command: str | None = None
    decisions: dict[str, list[Any]] = field(default_factory=dict)
    entities: dict[str, list[Any]] = field(default_factory=dict)
    gaps: dict[str, list[Any]] = field(default_factory=dict)
    days: dict[str, list[str]] = field(default_factory=dict)
    integrity_failed: int = 0
    first_cycle: int | None = None
    last_cycle: int | None = None
    _hours: dict[int, tuple[str, str]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from trace_audit.fleet.tables import schema

        for table in ("decisions", "entities", "gaps"):
            columns: dict[str, list[Any]] = {name: [] for name in schema(table).names}
            setattr(self, table, columns)
            self.days[table] = []

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
        self._decision(d, day, hour)
        if d.seal.gap is not None:
            self._gap(d, self._day_hour(d.seal.gap.after_t_ns)[0])
        if isinstance(d.perception, dict) and d.perception.get("entities"):
            self._entities(d, day)

    def _decision(self, d: ScoredDecision, day: str, hour: str) -> None:
        col = self.decisions
        self.days["decisions"].append(day)
        action = d.action if isinstance(d.action, dict) else {}
        execution = d.execution if isinstance(d.execution, dict) else {}
        rationale = action.get("rationale")
        raw_factors = rationale.get("factors") if isinstance(rationale, dict) else None
        factors = [
            {
                "node": str(f.get("node", "")),
                "name": str(f.get("name", "")),
                "value": _number(f.get("value")),
                "text": None if _number(f.get("value")) is not None else str(f.get("value")),
                "unit": f.get("unit"),
            }
            for f in raw_factors or ()
            if isinstance(f, dict)
        ]
        lead = factors[0] if factors else None
        command = action.get("command")
        session = self.segment.session
        score, seal = d.score, d.seal
        scenario = scenario_of(d.execution)
        intact = not seal.problems
        self.integrity_failed += not intact
        values: dict[str, Any] = {
            "segment": self.segment.path.name,
            "segment_path": str(self.segment.path),
            "tier": session.tier,
            "cycle": d.cycle.cycle,
            "t_ns": d.cycle.t_ns,
            "hour": hour,
            "command": command,
            "previous_command": self.previous_command,
            "lead_factor": (lead["name"] or lead["node"]) if lead else None,
            "lead_value": lead["value"] if lead else None,
            "lead_text": lead["text"] if lead else None,
            "lead_unit": lead["unit"] if lead else None,
            "factors": factors,
            "alternatives": len(action.get("alternatives") or ()),
            "counterfactuals": len(action.get("counterfactuals") or ()),
            "deviation": _number(execution.get("deviation")),
            "failed_checks": [
                str(c.get("rule"))
                for c in execution.get("checks") or ()
                if isinstance(c, dict) and c.get("passed") is False
            ],
            "flags": [str(f) for f in execution.get("flags") or ()],
            "scenario": None if scenario == NO_SCENARIO else scenario,
            "et": score.et,
            "et_partial": score.et_partial,
            "factors_total": score.factors,
            "factors_traceable": score.traceable,
            "dr": not d.dr_problems,
            "dr_problems": list(d.dr_problems),
            "sealed": seal.sealed,
            "seal_verified": intact,
            "integrity_problems": list(seal.problems),
            "summarized": d.cycle.summary is not None,
            "continuity": seal.continuity,
            "tcs": d.tcs,
            "window_ns": seal.window_ns,
            "gap_ns": seal.gap.gap_ns if seal.gap is not None else 0,
            "missing_cycles": seal.gap.missing_cycles if seal.gap is not None else 0,
            "dropped": seal.dropped,
            "clock_anomaly": seal.clock_anomaly,
            "software_version": session.software_version,
            "policy_version": session.policy_version,
        }
        for name, value in values.items():
            col[name].append(value)
        if command is not None:
            self.previous_command = str(command)

    def _gap(self, d: ScoredDecision, day: str) -> None:
        gap = d.seal.gap
        assert gap is not None  # the caller checked
        self.days["gaps"].append(day)
        values = {
            "segment": self.segment.path.name,
            "after_cycle": gap.after_cycle,
            "after_t_ns": gap.after_t_ns,
            "before_cycle": gap.before_cycle,
            "before_t_ns": gap.before_t_ns,
            "period_ns": gap.period_ns,
            "gap_ns": gap.gap_ns,
            "missing_cycles": gap.missing_cycles,
            "declared_dropped": gap.declared_dropped,
        }
        for name, value in values.items():
            self.gaps[name].append(value)

    def _entities(self, d: ScoredDecision, day: str) -> None:
        distances = _distances(d.belief)
        col = self.entities
        name = self.segment.path.name
        for entity in d.perception["entities"]:
            if not isinstance(entity, dict):
                continue
            cls = entity.get("class")
            confidence = entity.get("confidence")
            pose = entity.get("pose")
            position = pose.get("position") if isinstance(pose, dict) else None
            xy = position if isinstance(position, list | tuple) and len(position) >= 2 else None
            entity_id = str(entity.get("id", ""))
            self.days["entities"].append(day)
            col["segment"].append(name)
            col["cycle"].append(d.cycle.cycle)
            col["t_ns"].append(d.cycle.t_ns)
            col["entity"].append(entity_id)
            col["class"].append(None if cls is None else str(cls))
            col["confidence"].append(
                _number(confidence.get(cls)) if isinstance(confidence, dict) else None
            )
            col["distance"].append(distances.get(entity_id))
            col["x"].append(_number(xy[0]) if xy is not None else None)
            col["y"].append(_number(xy[1]) if xy is not None else None)
            col["evidence"].append(len(entity.get("evidence") or ()))

    def table(self, name: str) -> tuple[pa.Table, list[str]]:
        """One table's rows as Arrow, and the partition day of each row."""
        import pyarrow as pa

        from trace_audit.fleet.tables import schema

        columns: dict[str, list[Any]] = getattr(self, name)
        return pa.table(columns, schema=schema(name)), self.days[name]
