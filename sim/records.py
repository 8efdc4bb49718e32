"""Turn the pipeline's internal results into TRACE layer records (as dicts the logger checks).

The records are plain dicts all the way down, evidence refs and the decision tree included:
the logger validates a plain dict with its msgspec mirror, and sends a dict holding a model
down pydantic's slower path (44 instead of 78 us a cycle for the four layers, the same bytes).

This is also where the audit-trail faults bite: a corrupted evidence link, a belief edge
that was not written, a rationale written into a buffer that is too small.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import orjson

from sim.belief import BeliefGraph, Edge
from sim.counterfactual import Found
from sim.execution import Executed
from sim.perception import EvidenceItem, PerceptionOutput
from sim.policy import TREE, TREE_EDGES, Outcome, Scored
from trace_runtime import DecisionTree

RATIONALE_CAPACITY = 1024
DANGLING_SHIFT_NS = 37_000_000  # between two 10 Hz cycles: no sensor message is ever there

_TREE_NODES = [{"id": s.id, "label": s.label, "test": s.test, "command": s.command} for s in TREE]
_TREE_EDGES = [{"parent": p, "child": c, "label": lbl} for p, c, lbl in TREE_EDGES]
_TREES: dict[tuple[str, ...], dict[str, Any]] = {}


def _tree(path: tuple[str, ...]) -> dict[str, Any]:
    """The decision tree with its taken path, as a plain dict built once per path (there are
    five) and validated as a ``DecisionTree`` then, so a bad tree fails at once. Handed over
    as a dict: a model nested in a record sends the whole record down the logger's pydantic
    path, which costs more than its mirror checking the 21 nodes and edges each cycle."""
    tree = _TREES.get(path)
    if tree is None:
        tree = {"nodes": _TREE_NODES, "edges": _TREE_EDGES, "taken_path": list(path)}
        DecisionTree.model_validate(tree)
        _TREES[path] = tree
    return tree


_REGION_FRAME = {"beams": "lidar", "pixels": "camera", "cone": "ultrasonic", "box": "base_link"}


def _quat(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, round(math.sin(yaw / 2), 6), round(math.cos(yaw / 2), 6))


def _ref(ref: Any, corruption: str | None) -> Any:
    if corruption is None:
        # A logger's ``EvidenceRef`` as the plain dict of its fields (a pydantic model keeps
        # exactly its fields in ``__dict__``, never mutated here); a null logger's slotted
        # ref has none and is passed as it is (that logger reads nothing).
        return getattr(ref, "__dict__", ref)
    if corruption == "null":
        return None
    return {"topic": ref.topic, "log_time_ns": ref.log_time_ns + DANGLING_SHIFT_NS}


def _evidence(items: Iterable[EvidenceItem], corruption: str | None) -> list[dict[str, Any]]:
    return [
        {
            "sensor": e.sensor,
            "weight": e.weight,
            "region": {
                "kind": e.region_kind,
                "values": list(e.region_values),
                "frame": _REGION_FRAME[e.region_kind],
            },
            "ref": _ref(e.ref, corruption),
        }
        for e in items
    ]


def perception_record(
    out: PerceptionOutput,
    pose: tuple[float, float, float],
    corrupt: dict[str, str],
) -> dict[str, Any]:
    """Layer 1 record; ``corrupt`` maps entity id -> ``null`` | ``dangling``."""
    entities = []
    for e in out.entities:
        speed = math.hypot(e.vx, e.vy)
        yaw = math.atan2(e.vy, e.vx) if speed > 0.2 else 0.0
        entities.append(
            {
                "id": e.id,
                "class": e.cls,
                "pose": {
                    "position": (round(e.x, 3), round(e.y, 3), 0.0),
                    "orientation": _quat(yaw),
                },
                "velocity": (round(e.vx, 3), round(e.vy, 3), 0.0),
                "confidence": e.confidence,
                "evidence": _evidence(e.evidence, corrupt.get(e.id)),
            }
        )
    ox, oy, h = pose
    heading = _quat(h)  # the corridor's orientation and the robot's
    c = out.corridor
    ahead = min(c.clearance, c.length)
    entities.append(
        {
            "id": "corridor",
            "class": "corridor",
            "pose": {
                "position": (
                    round(ox + ahead * math.cos(h), 3),
                    round(oy + ahead * math.sin(h), 3),
                    0.0,
                ),
                "orientation": heading,
            },
            "confidence": {"corridor": 0.99},
            "evidence": _evidence(c.evidence, corrupt.get("corridor")),
        }
    )
    return {
        "entities": entities,
        "sensors_used": list(out.sensors_used),
        "sensors_unavailable": list(out.sensors_unavailable),
        # where the robot itself was: the incident report's scene places it by this
        "robot_pose": {"position": (round(ox, 3), round(oy, 3), 0.0), "orientation": heading},
    }


def belief_record(graph: BeliefGraph, skip: Edge | None = None) -> dict[str, Any]:
    """Layer 2 record; ``skip`` is an edge whose write failed."""
    return {
        "nodes": [
            {
                "id": n.id,
                "kind": n.kind,
                "label": n.label,
                "p": n.p,
                "value": n.value,
                "unit": n.unit,
                "entity": n.entity,
            }
            for n in graph.nodes
        ],
        "edges": [
            {"parent": e.parent, "child": e.child, "p": e.p, "rule": e.rule}
            for e in graph.edges
            if e is not skip
        ],
    }


class RationaleBuffer:
    """A bounded buffer for the rationale: text pieces and factors share ``capacity`` bytes.

    When a piece does not fit, what fits of its text is kept, nothing more is accepted,
    and the rationale is marked truncated.
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.used = 0
        self.pieces: list[str] = []
        self.factors: list[dict[str, Any]] = []
        self.truncated = False

    def add_text(self, piece: str) -> None:
        if self.truncated:
            return
        data = piece.encode()
        room = self.capacity - self.used
        if len(data) > room:
            self.pieces.append(data[: max(0, room)].decode(errors="ignore"))
            self.used = self.capacity
            self.truncated = True
            return
        self.pieces.append(piece)
        self.used += len(data)

    def add_factor(self, factor: dict[str, Any]) -> None:
        if self.truncated:
            return
        size = len(orjson.dumps(factor))
        if size > self.capacity - self.used:
            self.used = self.capacity
            self.truncated = True
            return
        self.factors.append(factor)
        self.used += size

    def rationale(self) -> dict[str, Any]:
        return {"text": "".join(self.pieces), "factors": self.factors, "truncated": self.truncated}


def write_rationale(
    buffer: RationaleBuffer,
    phrases: list[str],
    tests: tuple[tuple[str, str | None], ...],
    command: str,
    graph: BeliefGraph,
    *,
    factors: list[str] | None = None,
) -> None:
    """Write the rationale: each test's phrase, then the node it tested; then each other
    factor (one the taken path did not test) with its value; then the command."""
    nodes = {n.id: n for n in graph.nodes}
    seen: set[str] = set()

    def factor(node: str) -> None:
        seen.add(node)
        n = nodes[node]
        buffer.add_factor(
            {"node": node, "name": node.rsplit(".", 1)[-1], "value": n.value, "unit": n.unit}
        )

    for i, ((_, node), phrase) in enumerate(zip(tests, phrases, strict=True)):
        buffer.add_text(("" if i == 0 else "; ") + phrase)
        if node is not None and node not in seen:
            factor(node)
    for node in factors or ():
        if node not in seen:
            value = nodes[node].value
            shown = f"{value:.2f}" if isinstance(value, float) else str(value)
            buffer.add_text(f"; also read on the branches not taken: {node} {shown}")
            factor(node)
    buffer.add_text(f" -> {command}")


def rationale_size(
    phrases: list[str],
    tests: tuple[tuple[str, str | None], ...],
    command: str,
    graph: BeliefGraph,
    *,
    factors: list[str] | None = None,
) -> int:
    """Bytes the full rationale needs."""
    probe = RationaleBuffer(1 << 30)
    write_rationale(probe, phrases, tests, command, graph, factors=factors)
    return probe.used


def alternative_records(alternatives: list[Scored]) -> list[dict[str, Any]]:
    """The alternatives as the action record lists them."""
    return [
        {"command": a.command, "score": a.score, "rejected_because": a.rejected_because}
        for a in alternatives
    ]


def counterfactual_records(found: list[Found]) -> list[dict[str, Any]]:
    """The counterfactuals as the action record lists them."""
    return [
        {
            "factor": c.factor,
            "comparison": c.comparison,
            "threshold": c.threshold,
            "would_select": c.would_select,
        }
        for c in found
    ]


def action_record(
    outcome: Outcome,
    *,
    score: float,
    alternatives: list[dict[str, Any]],
    rationale: dict[str, Any],
    counterfactuals: list[dict[str, Any]] | None,
    intended: tuple[float, float],
) -> dict[str, Any]:
    """Layer 3 record; ``counterfactuals`` None means probing did not finish."""
    return {
        "command": outcome.command,
        "parameters": {"linear": intended[0], "angular": intended[1]},
        "score": score,
        "alternatives": alternatives,
        "rationale": rationale,
        "counterfactuals": counterfactuals or [],
        "counterfactuals_none_applicable": counterfactuals is not None and not counterfactuals,
        "tree": _tree(outcome.path),
    }


def execution_record(executed: Executed, flags: list[str]) -> dict[str, Any]:
    """Layer 4 record."""
    return {
        "intended": {"linear": executed.intended[0], "angular": executed.intended[1]},
        "actual": {"linear": executed.actual[0], "angular": executed.actual[1]},
        "deviation": executed.deviation,
        "checks": [
            {
                "rule": c.rule,
                "passed": c.passed,
                "value": c.value,
                "limit": c.limit,
                "detail": c.detail,
            }
            for c in executed.checks
        ],
        "flags": flags,
    }


# --- chain analysis (used to aim the edge fault and to describe what faults touched) ----


def _parents(edges: Iterable[Edge]) -> dict[str, list[Edge]]:
    out: dict[str, list[Edge]] = {}
    for e in edges:
        out.setdefault(e.child, []).append(e)
    return out


def reaches_entity(node: str, edges: Iterable[Edge], entities: set[str]) -> bool:
    """Whether ``node`` has a path of edges (child -> parent) up to an entity node."""
    parents = _parents(edges)
    stack, seen = [node], {node}
    while stack:
        n = stack.pop()
        if n in entities:
            return True
        for e in parents.get(n, ()):
            if e.parent not in seen:
                seen.add(e.parent)
                stack.append(e.parent)
    return False


def entities_under(node: str, edges: Iterable[Edge], entities: set[str]) -> set[str]:
    """Entity nodes that ``node``'s chains reach."""
    parents = _parents(edges)
    stack, seen = [node], {node}
    found = set()
    while stack:
        n = stack.pop()
        if n in entities:
            found.add(n)
        for e in parents.get(n, ()):
            if e.parent not in seen:
                seen.add(e.parent)
                stack.append(e.parent)
    return found


def cut_edges(node: str, edges: tuple[Edge, ...], entities: set[str]) -> list[Edge]:
    """Edges whose loss alone disconnects ``node`` from every entity node."""
    ancestors_edges = []
    parents = _parents(edges)
    stack, seen = [node], {node}
    while stack:
        n = stack.pop()
        for e in parents.get(n, ()):
            ancestors_edges.append(e)
            if e.parent not in seen:
                seen.add(e.parent)
                stack.append(e.parent)
    return [
        e
        for e in ancestors_edges
        if not reaches_entity(node, [x for x in edges if x is not e], entities)
    ]
