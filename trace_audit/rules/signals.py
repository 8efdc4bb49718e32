"""The signals a rule reads, by name, from one logged cycle.

A rule's formula names signals in eight families (docs/rules.md):

- ``command.<ACTION>``: 1.0 while the cycle's command is ACTION (matched without regard to
  case, as ``why`` does), else 0.0.
- ``channel.<name>.intended|actual|deviation``: an actuator channel (profile 1.1) in its own
  unit. A planar record's linear motion is ``channel.speed.*`` (speeds, m/s, as magnitudes;
  its deviation ``|actual - intended|``), unless the record names a ``speed`` channel itself.
- ``nearest.<class>``: the distance to the nearest perceived entity of that class, in metres,
  from the belief graph's distance nodes (a state node in metres whose label or id says
  ``distance``, with an edge from the entity); +inf when no entity of the class has one.
- ``factor.<node>`` or ``factor.<name>``: a factor value the decision names (booleans 0/1).
- ``check.<rule>``: 1.0 when that execution check passed, 0.0 when it failed.
- ``flag.<name>``: 1.0 when the execution record raises that flag, else 0.0.
- ``perception.sensors_unavailable`` / ``perception.sensors_used``: how many sensors the
  perception record lists there; ``perception.sensors_unavailable.<sensor>`` (or
  ``sensors_used.<sensor>``): 1.0 when it lists that sensor, else 0.0.
- ``evidence.age_s``: the age in seconds, at the decision, of the oldest reading its
  evidence refs (and its actuator channels' refs) cite; ``evidence.age_s.<sensor>``: of
  that sensor's readings (a channel's: its name). ``trace_audit.sensor_health`` computes
  the ages, as ``explain`` shows them.

A cycle that does not log what a signal is read from (no action, no execution record, no
perception, a check it did not run, a factor it does not name) has no value for it: the
signal is *missing* there, never guessed (``read_signals`` leaves it out).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, TypeVar

from trace_audit.causal.distances import entity_distances
from trace_audit.causal.lenient import (
    as_float,
    as_list,
    as_mapping,
    as_number_or_flag,
    as_str,
    mappings,
)
from trace_audit.sensor_health import cited_ages, sensor_names
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.partial import (
    RULES_ACTION,
    RULES_BELIEF,
    RULES_EXECUTION,
    RULES_PERCEPTION,
    read_layer,
)
from trace_runtime.flags import split_flags

if TYPE_CHECKING:  # numpy is imported by the index's reader, not by a log's
    import numpy as np
    from numpy.typing import NDArray

__all__ = [
    "FAMILIES",
    "SIGNAL_PATTERN",
    "bad_signal",
    "command_signal",
    "is_indicator",
    "nearest_by_class",
    "nearest_signal",
    "planar_speed",
    "read_signals",
    "signal_names",
]

FAMILIES = ("command", "channel", "nearest", "factor", "check", "flag", "perception", "evidence")
"""The first word of every signal name."""

SIGNAL_PATTERN = re.compile(rf"\b(?:{'|'.join(FAMILIES)})(?:\.[A-Za-z0-9_]+)+")
"""A signal name in a formula: a family, then dot-separated words of letters, digits, ``_``."""

_CHANNEL_PARTS = ("intended", "actual", "deviation")
_SENSOR_LISTS = ("sensors_unavailable", "sensors_used")
_AGE = "age_s"

Speed = TypeVar("Speed", float, "NDArray[np.float64]")
"""A linear speed in m/s: one cycle's, or a column of the fleet index's rows."""


def signal_names(formula: str) -> tuple[str, ...]:
    """The signal names a formula uses, each once, in order of first use."""
    return tuple(dict.fromkeys(m.group(0) for m in SIGNAL_PATTERN.finditer(formula)))


def bad_signal(name: str) -> str | None:
    """Why ``name`` is not a signal name a cycle can give, or None when it is one."""
    family, _, rest = name.partition(".")
    if family == "channel":
        channel, _, part = rest.rpartition(".")
        if not channel or part not in _CHANNEL_PARTS:
            return f"{name}: a channel signal is channel.<name>.intended|actual|deviation"
    elif family == "command" and "." in rest:
        return f"{name}: a command signal is command.<ACTION>"
    elif family == "perception" and rest.partition(".")[0] not in _SENSOR_LISTS:
        return (
            f"{name}: a perception signal is perception.sensors_unavailable|sensors_used[.<sensor>]"
        )
    elif family == "evidence" and rest.partition(".")[0] != _AGE:
        return f"{name}: an evidence signal is evidence.age_s[.<sensor>]"
    return None


def is_indicator(name: str) -> bool:
    """Whether a signal is 1.0 or 0.0 only, and "seen" in a log when it is ever 1.0: a
    command in force, a flag raised, a sensor listed (``perception.<list>.<sensor>``)."""
    family, _, rest = name.partition(".")
    return family in ("command", "flag") or (family == "perception" and "." in rest)


def read_signals(cycle: Cycle, names: Iterable[str]) -> tuple[str | None, dict[str, float]]:
    """The command in force in ``cycle`` (None: no action logged) and the value of each
    named signal; a signal the cycle does not log is left out.

    Read straight from the layers' bytes, only the fields the signals read
    (``trace_runtime.encoding.partial``'s rules shapes, the full JSON where a shape declines), as
    leniently as the decision view reads them (``trace_audit.causal.lenient``: a value of
    the wrong type is absent); no schema default changes a signal, so none is filled in.
    ``tests/trace_audit/rules`` pins every family to the values of the ``Decision`` view."""
    action = as_mapping(read_layer(cycle, RULES_ACTION))
    command = as_str(action.get("command")) if action is not None else None
    wanted = tuple(name.partition(".") for name in names)
    families = {family for family, _, _ in wanted}
    execution = (
        as_mapping(read_layer(cycle, RULES_EXECUTION))
        if families & {"channel", "check", "flag"}
        else None
    )
    nearest = nearest_by_class(cycle) if "nearest" in families else None
    perception = (
        read_layer(cycle, RULES_PERCEPTION) if families & {"perception", "evidence"} else None
    )
    if "evidence" in families and execution is None:
        execution = as_mapping(read_layer(cycle, RULES_EXECUTION))
    out: dict[str, float] = {}
    for (family, _, rest), name in zip(wanted, names, strict=True):
        if family == "command":
            value = command_signal(command, rest)
        elif family == "nearest":
            value = None if nearest is None else nearest_signal(nearest, rest)
        elif family == "factor":
            value = _factor_signal(action, rest)
        elif family == "perception":
            value = _sensor_list_signal(perception, rest)
        elif family == "evidence":
            value = _age_signal(perception, execution, cycle.t_ns, rest)
        elif execution is None:
            value = None
        elif family == "check":
            passed = [
                bool(c.get("passed"))
                for c in mappings(execution.get("checks"))
                if (as_str(c.get("rule")) or "?") == rest
            ]
            value = (1.0 if all(passed) else 0.0) if passed else None
        elif family == "flag":
            problems, _ = split_flags(as_list(execution.get("flags")))
            value = 1.0 if rest in problems else 0.0
        else:  # channel
            channel, _, part = rest.rpartition(".")
            value = _channel(execution, channel, part)
        if value is not None:
            out[name] = value
    return command, out


def _sensor_list_signal(perception: object, wanted: str) -> float | None:
    """``perception.<list>`` (how many it names) or ``perception.<list>.<sensor>`` (0/1);
    None when the cycle logs no perception."""
    if as_mapping(perception) is None:
        return None
    key, _, sensor = wanted.partition(".")
    names = sensor_names(perception, key)
    if not sensor:
        return float(len(names))
    return 1.0 if sensor in names else 0.0


def _age_signal(perception: object, execution: object, t_ns: int, wanted: str) -> float | None:
    """``evidence.age_s[.<sensor>]``: seconds from the oldest cited reading (of that sensor)
    to the decision; None when the cycle cites none."""
    _, _, sensor = wanted.partition(".")
    ages = [
        c.age_ns
        for c in cited_ages(perception, execution, t_ns)
        if not sensor or c.sensor == sensor
    ]
    return max(ages) / 1e9 if ages else None


def _factor_signal(action: Mapping[str, object] | None, wanted: str) -> float | None:
    rationale = as_mapping(action.get("rationale")) if action is not None else None
    for factor in mappings(rationale.get("factors") if rationale is not None else None):
        if wanted in (as_str(factor.get("node")) or "", as_str(factor.get("name")) or ""):
            return as_number_or_flag(factor.get("value"))
    return None


def _channel(execution: Mapping[str, object], name: str, part: str) -> float | None:
    for channel in mappings(execution.get("channels")):
        if (as_str(channel.get("name")) or "?") == name:
            return as_float(channel.get(part)) if part in _CHANNEL_PARTS else None
    if name != "speed":
        return None
    intended = as_mapping(execution.get("intended"))
    actual = as_mapping(execution.get("actual"))
    if intended is None and actual is None:
        return None  # not a planar record
    if part not in _CHANNEL_PARTS:
        return None
    value = planar_speed(
        part,
        _linear(intended),
        _linear(actual),
    )
    return None if math.isnan(value) else value


def _linear(motion: Mapping[str, object] | None) -> float:
    value = as_float(motion.get("linear")) if motion is not None else None
    return math.nan if value is None else value


def planar_speed(part: str, intended: Speed, actual: Speed) -> Speed:
    """``channel.speed.<part>`` (``intended``, ``actual`` or ``deviation``) of a planar
    record whose linear motion was ``intended`` and ``actual`` (m/s, signed as logged, NaN
    when not logged): the speeds as magnitudes, the deviation ``|actual - intended|``; NaN
    when what it needs is not logged. Elementwise over numpy columns too: the one rule for
    a log's cycles and the fleet index's rows."""
    if part == "intended":
        return abs(intended)
    if part == "actual":
        return abs(actual)
    return abs(actual - intended)


def command_signal(command: str | None, action: str) -> float | None:
    """``command.<action>`` for a cycle whose command is ``command`` (None: none logged)."""
    if command is None:
        return None
    return 1.0 if command.casefold() == action.casefold() else 0.0


def nearest_signal(nearest: Mapping[str, float], cls: str) -> float:
    """``nearest.<cls>`` from a cycle's class -> nearest distance (+inf: none of the class
    perceived). A cycle without perception has no value: the caller leaves it out."""
    return nearest.get(cls, math.inf)


def nearest_by_class(cycle: Cycle) -> dict[str, float] | None:
    """Entity class -> nearest distance in metres this cycle (None: no perception logged)."""
    perception = as_mapping(read_layer(cycle, RULES_PERCEPTION))
    if perception is None:
        return None
    distances = entity_distances(read_layer(cycle, RULES_BELIEF))
    nearest: dict[str, float] = {}
    for entity in mappings(perception.get("entities")):
        cls = as_str(entity.get("class"))
        distance = distances.get(as_str(entity.get("id")) or "")
        if cls is not None and distance is not None:
            nearest[cls] = min(distance, nearest.get(cls, distance))
    return nearest
