"""Single fields of a logged cycle, read without parsing its whole record where bytes allow.

The timeline, ``why``, ``explain`` and ``info`` read one field of every cycle (the command,
the execution flags, the seal's ``dropped``); these read it from the canonical bytes and
fall back to the full parse for anything else.
"""

from __future__ import annotations

import orjson

from trace_runtime.encoding.cycles import Cycle
from trace_runtime.records import TOPIC_ACTION, TOPIC_EXECUTION, TOPIC_SEAL

__all__ = ["command_of", "execution_fields", "is_decision_change", "seal_dropped"]


def is_decision_change(seen_before: bool, previous: str | None, command: str | None) -> bool:
    """The one definition of a decision change (``timeline``, the Foxglove export): a cycle
    whose command differs from the cycle before it (``previous``). A robot's first
    decision (``seen_before`` False) is where its record starts, not a change."""
    return seen_before and command != previous


def command_of(cycle: Cycle) -> str | None:
    """The command of a cycle's action, read without parsing the whole record."""
    data = cycle.payloads.get(TOPIC_ACTION)
    if data is not None:
        # Canonical bytes put the action's own "command" first after the stamp; anything
        # else (another writer's key order, escapes) takes the full parse below.
        at = data.find(b'"command":"')
        if at > 0 and data.count(b"{", 0, at) == 1:
            end = data.find(b'"', at + 11)
            value = data[at + 11 : end]
            if end > 0 and b"\\" not in value:
                return value.decode()
    layer = cycle.layer(TOPIC_ACTION)
    if isinstance(layer, dict):
        command = layer.get("command")
        return command if isinstance(command, str) else None
    return None


def execution_fields(cycle: Cycle) -> tuple[tuple[str, ...], float | None, str | None]:
    """The execution record's flags, overall deviation and its unit (one parse a cycle)."""
    data = cycle.payloads.get(TOPIC_EXECUTION)
    layer = orjson.loads(data) if data is not None else cycle.layer(TOPIC_EXECUTION)
    if not isinstance(layer, dict):
        return (), None, None
    flags = tuple(f for f in layer.get("flags") or () if isinstance(f, str))
    deviation = layer.get("deviation")
    unit = layer.get("deviation_unit")
    return (
        flags,
        float(deviation) if isinstance(deviation, int | float) else None,
        unit if isinstance(unit, str) and unit else None,
    )


def seal_dropped(cycle: Cycle) -> int:
    """The ``dropped`` count of the cycle's seal (0 unsealed or none given)."""
    data = cycle.payloads.get(TOPIC_SEAL)
    if data is None:
        return 0
    at = data.rfind(b'"dropped":')
    if at < 0:
        return 0
    digits = bytearray()
    for byte in data[at + 10 :]:
        if 48 <= byte <= 57:
            digits.append(byte)
        else:
            break
    return int(digits) if digits else 0
