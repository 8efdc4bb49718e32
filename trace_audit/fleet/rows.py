"""One segment's rows of the fleet index, built from the decisions metrics scored.

``SegmentRows`` is a ``trace_audit.metrics.DecisionSink``: metrics reads the segment and
scores each decision once (ET, ET_partial, DR, the seal check, the gap rule); this module
only copies those figures and the parsed layers' fields into columns. Nothing here scores.

Each row goes under a ``day`` partition (``partition_of``): on a wall clock the UTC day of
its time; on a sim or monotonic clock, whose times count from an arbitrary zero, the
robot's run (``run-<number of the run's first segment>``), never a day of 1970.

The rows are built for speed (bench/bench_fleet.py, docs/fleet.md "Build cost"): a row is
one tuple of plain scalars, and the list-, struct- and map-valued columns are kept flat
(one list of values and one of offsets per column), so a decision adds no Python
container that lives on: the cyclic garbage collector, which walks every live container,
then has almost nothing to walk while metrics allocates. Columns that are the same for
every row of a segment (its name, path, tier, versions) are filled once, in ``table``.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from trace_audit.causal.distances import entity_distances
from trace_audit.causal.lenient import as_number_or_flag
from trace_audit.columns import gap_row
from trace_audit.log_time import hour_of
from trace_audit.metrics import NO_SCENARIO, ScoredDecision, scenario_of
from trace_audit.metrics.sums import failed_check_rules
from trace_runtime.clock import is_wall_clock
from trace_runtime.reading.reader import Segment

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["ROW_TABLES", "SegmentRows", "day_of", "partition_of"]

_HOUR_NS = 3_600_000_000_000
_SEGMENT_CONSTANTS = ("segment", "segment_path", "tier", "software_version", "policy_version")
"""Decision columns equal on every row of a segment: not stored per row."""
_FLAT = ("factors", "failed_checks", "flags", "nearest", "dr_problems", "integrity_problems")
"""Decision columns holding a list (or map) per row: kept as flat values and offsets."""
_FACTOR_FIELDS = ("node", "name", "value", "text", "unit")
ROW_TABLES = ("decisions", "entities", "channels", "checks", "gaps")
"""The tables filled decision by decision (``segments`` has one row, made by the index)."""


def day_of(t_ns: int) -> str:
    """The UTC day of a wall-clock time, ``YYYY-MM-DD`` (the index's partition value)."""
    return time.strftime("%Y-%m-%d", time.gmtime(t_ns // 1_000_000_000))


def partition_of(clock: str, start_ns: int, first_segment: int) -> str | None:
    """The ``day`` partition of every row of a robot's run on ``clock`` starting at
    ``start_ns`` whose first segment is ``first_segment``: None on a wall clock (each row
    goes under its own UTC day, ``day_of``), else ``run-<first segment>``."""
    if is_wall_clock(clock, start_ns):
        return None
    return f"run-{first_segment:06d}"


def _text(value: object) -> str | None:
    return None if value is None else str(value)


def _linear(motion: object) -> float | None:
    """A planar ``Motion``'s linear m/s, as logged (None: no planar motion)."""
    return as_number_or_flag(motion.get("linear")) if type(motion) is dict else None


@dataclass(slots=True)
class _Flat:
    """A list-valued column kept flat: every row's items in one list, and where each row
    ends (Arrow's own layout, so the column is built without a Python list per row)."""

    offsets: list[int] = field(default_factory=lambda: [0])
    items: list[object] = field(default_factory=list)
    """Cells of the column's item type (pyarrow converts them: ``array``)."""

    def add(self, items: Sequence[object]) -> None:
        if items:
            self.items.extend(items)
        self.offsets.append(len(self.items))

    def array(self, item_type: pa.DataType) -> pa.Array:
        import pyarrow as pa

        return pa.ListArray.from_arrays(
            pa.array(self.offsets, pa.int32()),
            pa.array(self.items, item_type),
            type=pa.list_(item_type),
        )


@dataclass(slots=True)
class SegmentRows:
    """The decisions, entities and gaps of one segment, filled decision by decision."""

    segment: Segment
    previous_command: str | None = None
    run: str | None = None
    """The run's partition (``partition_of``) on a sim or monotonic clock; None: by UTC day."""
    rows: dict[str, list[tuple[Any, ...]]] = field(default_factory=dict)
    """Per table, one tuple of scalars per row (the decisions' flat columns excluded)."""
    days: dict[str, list[str]] = field(default_factory=dict)
    integrity_failed: int = 0
    first_cycle: int | None = None
    last_cycle: int | None = None
    flat: dict[str, _Flat] = field(default_factory=dict)
    _factor_items: tuple[list[Any], ...] = ()
    _nearest_values: list[float] = field(default_factory=list)
    _hours: dict[int, tuple[str, str]] = field(default_factory=dict)
    _name: str = ""

    def __post_init__(self) -> None:
        for table in ROW_TABLES:
            self.rows[table] = []
            self.days[table] = []
        self.flat = {name: _Flat() for name in _FLAT}
        self._factor_items = tuple([] for _ in _FACTOR_FIELDS)
        self._name = self.segment.path.name

    @property
    def decisions(self) -> int:
        return len(self.rows["decisions"])

    def _day_hour(self, t_ns: int) -> tuple[str, str]:
        """The row's partition (the UTC day, or the run on a sim or monotonic clock) and its
        ``hour`` as ``metrics --by hour`` groups (``log_time.hour_of``) (so the index's
        groups are the logs')."""
        bucket = t_ns // _HOUR_NS
        found = self._hours.get(bucket)
        if found is None:
            hour = hour_of(t_ns, wall=self.run is None)
            day = hour[:10] if self.run is None else self.run
            found = self._hours[bucket] = (day, hour)
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
        execution = d.execution
        if type(execution) is dict:
            if execution.get("channels"):
                self._channels(d, execution, day)
            if execution.get("checks"):
                self._checks(d, execution["checks"], day)
        if d.seal.gap is not None:
            self._gap(d, self._day_hour(d.seal.gap.after_t_ns)[0])

    def _factors(self, rationale: object) -> tuple[str | None, float | None, str | None, object]:
        """Add the decision's factors to the flat ``factors`` column; return the leading
        one's name, value, text and unit (all None without factors)."""
        raw_factors = rationale.get("factors") if type(rationale) is dict else None
        nodes, names, values, texts, units = self._factor_items
        # The unit as logged (text, or whatever another writer put there: a string column).
        lead: tuple[str | None, float | None, str | None, object] = (None, None, None, None)
        count = 0
        for f in raw_factors or ():
            if type(f) is dict:
                raw = f.get("value")
                value = as_number_or_flag(raw)
                node, name = str(f.get("node", "")), str(f.get("name", ""))
                text = None if value is not None else str(raw)
                unit = f.get("unit")
                if not count:
                    lead = (name or node, value, text, unit)
                count += 1
                nodes.append(node)
                names.append(name)
                values.append(value)
                texts.append(text)
                units.append(unit)
        factors = self.flat["factors"]
        factors.offsets.append(factors.offsets[-1] + count)
        return lead

    def _decision(self, d: ScoredDecision, day: str, hour: str, nearest: dict[str, float]) -> None:
        self.days["decisions"].append(day)
        action = d.action if type(d.action) is dict else {}
        execution = d.execution if type(d.execution) is dict else {}
        lead_factor, lead_value, lead_text, lead_unit = self._factors(action.get("rationale"))
        command = action.get("command")
        score, seal = d.score, d.seal
        scenario = scenario_of(execution)
        intact = not seal.problems
        self.integrity_failed += not intact
        gap = seal.gap
        flat = self.flat
        flat["failed_checks"].add(failed_check_rules(execution))
        flat["flags"].add([str(f) for f in execution.get("flags") or ()])
        flat["nearest"].add(tuple(nearest))
        if nearest:
            self._nearest_values.extend(nearest.values())
        flat["dr_problems"].add(d.dr_problems)
        flat["integrity_problems"].add(seal.problems)
        self.rows["decisions"].append(
            (
                d.cycle.cycle,
                d.cycle.t_ns,
                hour,
                command,
                self.previous_command,
                lead_factor,
                lead_value,
                lead_text,
                lead_unit,
                len(action.get("alternatives") or ()),
                len(action.get("counterfactuals") or ()),
                as_number_or_flag(execution.get("deviation")),
                _text(execution.get("deviation_unit")),
                _linear(execution.get("intended")),
                _linear(execution.get("actual")),
                None if scenario == NO_SCENARIO else scenario,
                score.et if score.known else None,  # unknown is null, never 0
                score.et_partial if score.known else None,
                score.factors,
                score.traceable,
                not d.dr_problems,
                seal.sealed,
                intact,
                d.cycle.summary is not None,
                seal.continuity,
                d.tcs,
                seal.window_ns,
                gap.gap_ns if gap is not None else 0,
                gap.missing_cycles if gap is not None else 0,
                seal.dropped,
                seal.clock_anomaly,
            )
        )
        if command is not None:
            self.previous_command = str(command)

    def _gap(self, d: ScoredDecision, day: str) -> None:
        gap = d.seal.gap
        assert gap is not None  # the caller checked
        self.days["gaps"].append(day)
        self.rows["gaps"].append(gap_row(self._name, gap))

    def _channels(self, d: ScoredDecision, execution: dict[str, object], day: str) -> None:
        """Add the cycle's actuator channel rows, each with the record's ``deviation_unit``."""
        channels = execution["channels"]
        if type(channels) is not list:
            return
        unit = _text(execution.get("deviation_unit"))
        rows, days = self.rows["channels"], self.days["channels"]
        number, t_ns = d.cycle.cycle, d.cycle.t_ns
        for channel in channels:
            if type(channel) is not dict:
                continue
            days.append(day)
            rows.append(
                (
                    number,
                    t_ns,
                    _text(channel.get("name")),
                    as_number_or_flag(channel.get("intended")),
                    as_number_or_flag(channel.get("actual")),
                    as_number_or_flag(channel.get("deviation")),
                    _text(channel.get("unit")),
                    unit,
                )
            )

    def _checks(self, d: ScoredDecision, checks: object, day: str) -> None:
        """Add the cycle's compliance check rows, one per rule checked."""
        if type(checks) is not list:
            return
        rows, days = self.rows["checks"], self.days["checks"]
        number, t_ns = d.cycle.cycle, d.cycle.t_ns
        for check in checks:
            if type(check) is not dict:
                continue
            passed = check.get("passed")
            days.append(day)
            rows.append(
                (
                    number,
                    t_ns,
                    _text(check.get("rule")),
                    passed if type(passed) is bool else None,
                    as_number_or_flag(check.get("value")),
                    as_number_or_flag(check.get("limit")),
                    _text(check.get("detail")),
                )
            )

    def _entities(
        self, d: ScoredDecision, entities: Iterable[object], day: str
    ) -> dict[str, float]:
        """Add the cycle's entity rows; return the nearest distance of each class seen."""
        distances = entity_distances(d.belief)
        nearest: dict[str, float] = {}
        rows = self.rows["entities"]
        days = self.days["entities"]
        number, t_ns = d.cycle.cycle, d.cycle.t_ns
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
                    number,
                    t_ns,
                    entity_id,
                    None if cls is None else str(cls),
                    as_number_or_flag(confidence.get(cls)) if type(confidence) is dict else None,
                    distance,
                    as_number_or_flag(xy[0]),
                    as_number_or_flag(xy[1]),
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
        if name == "decisions":
            return pa.Table.from_arrays(self._decision_arrays(shape), schema=shape), self.days[name]
        constant_segment = name != "gaps"  # not stored per row: filled here
        width = len(shape) - constant_segment
        columns: list[Any] = list(zip(*rows, strict=True)) if rows else [()] * width
        if constant_segment:
            columns.insert(0, [self._name] * len(rows))
        arrays = [pa.array(column, type=f.type) for column, f in zip(columns, shape, strict=True)]
        return pa.Table.from_arrays(arrays, schema=shape), self.days[name]

    def _decision_arrays(self, shape: pa.Schema) -> list[pa.Array]:
        """The decisions' columns in schema order: scalar ones from the row tuples, list
        ones from their flat values, the segment's constants repeated."""
        import pyarrow as pa

        rows = self.rows["decisions"]
        n = len(rows)
        session = self.segment.session
        constant = {
            "segment": self._name,
            "segment_path": str(self.segment.path),
            "tier": session.tier,
            "software_version": session.software_version,
            "policy_version": session.policy_version,
        }
        scalar_names = [
            f.name for f in shape if f.name not in _FLAT and f.name not in _SEGMENT_CONSTANTS
        ]
        columns = list(zip(*rows, strict=True)) if rows else [()] * len(scalar_names)
        scalars = dict(zip(scalar_names, columns, strict=True))
        arrays: list[pa.Array] = []
        for f in shape:
            if f.name in constant:
                arrays.append(pa.array([constant[f.name]] * n, f.type))
            elif f.name == "factors":
                arrays.append(self._factor_array(f.type))
            elif f.name == "nearest":
                flat = self.flat["nearest"]
                arrays.append(
                    pa.MapArray.from_arrays(
                        pa.array(flat.offsets, pa.int32()),
                        pa.array(flat.items, pa.string()),
                        pa.array(self._nearest_values, pa.float64()),
                        type=f.type,
                    )
                )
            elif f.name in _FLAT:
                arrays.append(self.flat[f.name].array(f.type.value_type))
            else:
                arrays.append(pa.array(scalars[f.name], f.type))
        return arrays

    def _factor_array(self, list_type: pa.DataType) -> pa.Array:
        import pyarrow as pa

        struct = list_type.value_type
        children = [
            pa.array(items, struct.field(i).type) for i, items in enumerate(self._factor_items)
        ]
        return pa.ListArray.from_arrays(
            pa.array(self.flat["factors"].offsets, pa.int32()),
            pa.StructArray.from_arrays(children, fields=list(struct)),
            type=list_type,
        )
