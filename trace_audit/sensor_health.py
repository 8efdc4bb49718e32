"""What a robot knew about its sensors when it decided: which it used, which it expected
but missed (``sensors_used`` / ``sensors_unavailable`` of its perception record, profile
1.0), and how old each reading it cited was.

The age of a cited reading is the decision's time minus the reading's log time (its
evidence ref's ``log_time_ns``; an actuator channel's ref counts too). A reading is *stale*
when it is older than the one gap rule allows between two cycles (``trace_runtime.gaps``:
1.5 periods by default): by then the robot should have had a fresher one. A reading logged
after the decision is not stale but odd (a ref to the future), and said so. ``explain``
shows all of it; the rules read the same numbers (``perception.*`` and ``evidence.age_s``
signals, docs/rules.md) through ``cited_ages``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from trace_audit.causal.lenient import as_list, as_mapping, as_str, mappings
from trace_runtime.gaps import gap_limit_ns

__all__ = ["CitedAge", "SensorHealth", "cited_ages", "sensor_health", "sensor_names"]


@dataclass(frozen=True, slots=True)
class CitedAge:
    """One reading a decision cited, and its age at the decision."""

    entity: str
    """The entity whose evidence cites it ('' for an actuator channel's ref)."""
    channel: str
    """The actuator channel whose ``actual`` was read from it ('' for an entity's)."""
    sensor: str
    """The evidence item's sensor name (a channel's ref: the channel's name)."""
    topic: str
    recording: str
    """The recording that holds it ('' when it is in this log)."""
    log_time_ns: int
    age_ns: int
    """Decision time - reading time; negative when the reading is later than the decision."""
    stale: bool
    """Older than the gap rule allows at the robot's period."""


@dataclass(frozen=True, slots=True)
class SensorHealth:
    """The sensors a decision used and missed, and the age of every reading it cited."""

    used: tuple[str, ...]
    unavailable: tuple[str, ...]
    """Sensors the robot expected but did not have this cycle (it said so)."""
    cited: tuple[CitedAge, ...]
    oldest_age_ns: int | None
    """The age of the oldest cited reading; None when the decision cites none."""
    stale_after_ns: int | None
    """Age beyond which a reading is stale (the gap limit); None when the period is unknown."""


def sensor_names(perception: object, key: str) -> tuple[str, ...]:
    """The sensor names a perception record lists under ``key`` (``sensors_used`` or
    ``sensors_unavailable``), each once, in order; anything that is not a name is skipped."""
    record = as_mapping(perception)
    names = as_list(record.get(key)) if record is not None else []
    return tuple(dict.fromkeys(n for n in names if isinstance(n, str)))


def cited_ages(
    perception: object, execution: object, t_ns: int, period_ns: int = 0
) -> tuple[CitedAge, ...]:
    """Every distinct reading a decision's layers (parsed JSON) cite, with its age at
    ``t_ns``; ``period_ns`` (0: unknown) decides which are stale."""
    limit = gap_limit_ns(period_ns) if period_ns > 0 else None
    seen: set[tuple[str, str, str, str, int]] = set()
    out: list[CitedAge] = []
    for entity, channel, sensor, ref in _refs(perception, execution):
        stamp = ref.get("log_time_ns")
        if type(stamp) is not int:
            continue
        topic = as_str(ref.get("topic")) or "?"
        recording = as_str(ref.get("recording")) or ""
        key = (entity, channel, topic, recording, stamp)
        if key in seen:
            continue
        seen.add(key)
        age = t_ns - stamp
        stale = limit is not None and age > limit
        out.append(CitedAge(entity, channel, sensor, topic, recording, stamp, age, stale))
    return tuple(out)


def _refs(
    perception: object, execution: object
) -> Iterator[tuple[str, str, str, Mapping[str, object]]]:
    """(entity, channel, sensor, ref) of every ref the perception and execution records hold."""
    record = as_mapping(perception)
    for entity in mappings(record.get("entities") if record is not None else None):
        entity_id = as_str(entity.get("id")) or "?"
        for evidence in mappings(entity.get("evidence")):
            ref = as_mapping(evidence.get("ref"))
            if ref is not None:
                yield entity_id, "", as_str(evidence.get("sensor")) or "?", ref
    done = as_mapping(execution)
    for channel in mappings(done.get("channels") if done is not None else None):
        ref = as_mapping(channel.get("ref"))
        if ref is not None:
            name = as_str(channel.get("name")) or "?"
            yield "", name, name, ref


def sensor_health(perception: object, execution: object, t_ns: int, period_ns: int) -> SensorHealth:
    """What the decision at ``t_ns`` knew about its sensors (see the module's docstring)."""
    cited = cited_ages(perception, execution, t_ns, period_ns)
    return SensorHealth(
        used=sensor_names(perception, "sensors_used"),
        unavailable=sensor_names(perception, "sensors_unavailable"),
        cited=cited,
        oldest_age_ns=max((c.age_ns for c in cited), default=None),
        stale_after_ns=gap_limit_ns(period_ns) if period_ns > 0 else None,
    )
