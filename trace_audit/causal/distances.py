"""How far each perceived entity is from the robot, as the belief graph says.

The one rule the fleet index's ``nearest`` column and the rules' ``nearest.<class>``
signals read: an entity's distance is a ``state`` node of the belief graph, labelled or
named ``distance``, in metres, with a documented edge from the entity's node. Where an
entity has several, the nearest counts. Nothing is computed from positions: a robot that
derives no distance has none.
"""

from __future__ import annotations

from trace_audit.causal.lenient import as_number_or_flag

__all__ = ["DISTANCE_UNITS", "entity_distances"]

DISTANCE_UNITS = frozenset(("m", "meter", "metre", "meters", "metres"))


def entity_distances(belief: object) -> dict[str, float]:
    """Entity id -> distance to the robot in metres, for a cycle's ``/trace/belief``
    record as parsed JSON (anything else gives none)."""
    if type(belief) is not dict:
        return {}
    values: dict[object, float] = {}
    for node in belief.get("nodes") or ():
        if (
            type(node) is dict
            and node.get("kind") == "state"
            and node.get("unit") in DISTANCE_UNITS
            and "distance" in f"{node.get('label', '')} {node.get('id', '')}".lower()
        ):
            value = as_number_or_flag(node.get("value"))
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
