"""Layer 2: the belief graph. Entity nodes, derived states, and edges with P(child | parent).

Node ids are stable and readable; the investigator and the metrics rely on them:

- ``<entity>`` (kind ``entity``, ``entity=<perception entity id>``, value = its class)
- ``<entity>.distance`` (m), parent ``<entity>``
- ``<entity>.intent`` (person: standing | crossing | approaching | leaving), parent ``<entity>``
- ``<entity>.conflict`` in [0, 1]: how close the entity's predicted path comes to the robot's
  (person: lateral conflict; forklift: miss distance, 0 unless seen moving), parent ``<entity>``
- ``<entity>.closing`` (forklift, m/s towards the robot), parent ``<entity>``
- ``<entity>.ttc`` (forklift, s, 99 = not closing), parents ``.distance`` and ``.closing``
- ``<entity>.collision_risk`` in [0, 1]; person: parents ``.distance``, ``.intent`` and
  ``.conflict``; forklift: parents ``.ttc`` and ``.conflict``
- ``corridor`` (entity), ``corridor.clearance`` (m), ``aisle_blocked`` (P(blocked)), parent
  ``corridor.clearance`` and, when an obstacle bounds the clearance, ``<obstacle>.distance``

Every derived value is a function of its parents' logged values only (``RULES``, keyed by the
edge's rule text), so an intervention on one node can be propagated to its descendants from
the logged graph alone (``intervene``): that is what the counterfactuals are.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from sim.perception import CORRIDOR_MAX_M, PerceivedEntity, PerceptionOutput
from trace_runtime.errors import TraceError

CRUISE_MPS = 1.2
TTC_CAP_S = 99.0
STATIONARY_MPS = 0.3
VEHICLE_MOVING_MPS = 0.5
_INTENT_WEIGHT = {"standing": 0.85, "crossing": 1.0, "approaching": 1.0, "leaving": 0.6}

RULE_RANGE = "range: |entity - robot| from the fused track position"
RULE_INTENT = "intent: entity velocity relative to the robot's heading"
RULE_PED_CONFLICT = (
    "conflict = exp(-(closest approach of the person's predicted path to the robot's path "
    "while the robot arrives at cruise / 0.8 m)^2)"
)
RULE_PED_RISK = "risk = conflict x proximity sigmoid((4.0 m - distance) / 1.2 m) x intent weight"
RULE_CLOSING = "closing = speed of the vehicle towards the robot, both as tracked"
RULE_TTC = "ttc = distance / closing speed (99 s when closing < 0.05 m/s)"
RULE_VEH_CONFLICT = (
    "conflict = exp(-(predicted miss distance beyond the robot's half width / 0.5 m)^2); "
    "0 unless the vehicle is seen moving at 0.5 m/s or more"
)
RULE_VEH_RISK = "risk = conflict x sigmoid((4.5 s - ttc) / 1.0 s)"
RULE_CLEARANCE = "clearance = nearest non-person LiDAR return inside the corridor"
RULE_BLOCKED = "P(blocked) = sigmoid((4.0 m - clearance) / 0.5 m)"
RULE_OBSTACLE = "obstacle bounds the corridor clearance"


def _entity_of(node: str) -> str:
    return node.rsplit(".", 1)[0]


def ped_risk(distance: float, intent: str, conflict: float) -> float:
    """A pedestrian's collision risk from its parents (``RULE_PED_RISK``)."""
    return round(conflict * _sigmoid((4.0 - distance) / 1.2) * _INTENT_WEIGHT[intent], 3)


def time_to_collision(distance: float, closing: float) -> float:
    """A vehicle's time to collision from its parents (``RULE_TTC``)."""
    return round(min(TTC_CAP_S, distance / closing), 3) if closing > 0.05 else TTC_CAP_S


def vehicle_risk(ttc: float, conflict: float) -> float:
    """A vehicle's collision risk from its parents (``RULE_VEH_RISK``)."""
    return round(conflict * _sigmoid((4.5 - ttc) / 1.0), 3)


def p_blocked(clearance: float) -> float:
    """P(aisle blocked) from the corridor clearance (``RULE_BLOCKED``)."""
    return round(_sigmoid((4.0 - clearance) / 0.5), 3)


Compute = Callable[[dict[str, object]], float]
"""A derived node's value from the current node values."""


@dataclass(frozen=True, slots=True)
class Rule:
    """How a derived node's value follows from its parents' (named from the child's id).

    ``bind(child)`` is the child's computation with its parents' ids worked out once: a
    plan is re-run dozens of times per probe."""

    bind: Callable[[str], Compute]
    parents: Callable[[str], tuple[str, ...]]


def _bind_ped_risk(child: str) -> Compute:
    e = _entity_of(child)
    d, i, c = f"{e}.distance", f"{e}.intent", f"{e}.conflict"
    return lambda v: ped_risk(float(v[d]), str(v[i]), float(v[c]))  # type: ignore[arg-type]


def _bind_ttc(child: str) -> Compute:
    e = _entity_of(child)
    d, c = f"{e}.distance", f"{e}.closing"
    return lambda v: time_to_collision(float(v[d]), float(v[c]))  # type: ignore[arg-type]


def _bind_veh_risk(child: str) -> Compute:
    e = _entity_of(child)
    t, c = f"{e}.ttc", f"{e}.conflict"
    return lambda v: vehicle_risk(float(v[t]), float(v[c]))  # type: ignore[arg-type]


def _bind_blocked(child: str) -> Compute:
    return lambda v: p_blocked(float(v["corridor.clearance"]))  # type: ignore[arg-type]


def _named(*suffixes: str) -> Callable[[str], tuple[str, ...]]:
    return lambda child: tuple(f"{_entity_of(child)}.{s}" for s in suffixes)


RULES: dict[str, Rule] = {
    RULE_PED_RISK: Rule(_bind_ped_risk, _named("distance", "intent", "conflict")),
    RULE_TTC: Rule(_bind_ttc, _named("distance", "closing")),
    RULE_VEH_RISK: Rule(_bind_veh_risk, _named("ttc", "conflict")),
    RULE_BLOCKED: Rule(_bind_blocked, lambda _: ("corridor.clearance",)),
}
"""Edge rule -> how the child's value follows from its parents' values. Rules not listed
(range, intent, conflict, closing, clearance) derive a node from sensor data, not from other
nodes: an intervention stops there. ``RULE_OBSTACLE`` names the obstacle behind a clearance
(the clearance is measured, not computed from that distance), so it propagates nothing."""


def missing_rule_edges(edges: Iterable[tuple[str, str, str]]) -> list[tuple[str, str]]:
    """(parent, child) edges that a derived node's rule reads but the graph lacks: where an
    intervention cannot be propagated from the graph alone."""
    have: dict[str, set[str]] = {}
    rule_of: dict[str, str] = {}
    for parent, child, rule in edges:
        if rule in RULES:
            have.setdefault(child, set()).add(parent)
            rule_of[child] = rule
    return [
        (parent, child)
        for child, rule in rule_of.items()
        for parent in RULES[rule].parents(child)
        if parent not in have[child]
    ]


class UnknownRuleError(TraceError):
    """A logged edge into a descendant names a rule this policy does not know."""


Plan = list[tuple[str, Compute]]


def intervention_plan(node: str, edges: Iterable[tuple[str, str, str]]) -> Plan:
    """The descendants of ``node`` that a ``do(node = x)`` changes, in an order where each
    comes after its parents, each with its rule. ``edges`` are (parent, child, rule)."""
    children: dict[str, list[str]] = {}
    parents: dict[str, list[str]] = {}
    rule_into: dict[str, set[str]] = {}
    for parent, child, rule in edges:
        if rule in RULES:
            children.setdefault(parent, []).append(child)
            parents.setdefault(child, []).append(parent)
            rule_into.setdefault(child, set()).add(rule)
    reached: set[str] = set()
    stack = [node]
    while stack:
        for child in children.get(stack.pop(), ()):
            if child not in reached:
                reached.add(child)
                stack.append(child)
    order: list[str] = []
    done = {node}

    def visit(n: str) -> None:
        # Parents first; the graph is a DAG by construction (entity -> state -> risk).
        if n in done:
            return
        done.add(n)
        for parent in parents.get(n, ()):
            if parent in reached:
                visit(parent)
        order.append(n)

    for n in sorted(reached):
        visit(n)
    plan = []
    for n in order:
        if len(rule_into[n]) != 1:
            raise UnknownRuleError(f"{n} is derived by {len(rule_into[n])} rules")
        plan.append((n, RULES[next(iter(rule_into[n]))].bind(n)))
    return plan


Edges = tuple[tuple[str, str, str], ...]


class PlanCache:
    """Intervention plans remembered per (graph edges, node), for the last ``size`` graph
    shapes. A plan is a pure function of the two, and a prober re-plans the same factors of
    the same graph shape cycle after cycle while the same entities are tracked."""

    def __init__(self, size: int = 64) -> None:
        self._size = size
        self._by_edges: dict[Edges, dict[str, Plan]] = {}

    def plan(self, node: str, edges: Edges) -> Plan:
        """``intervention_plan(node, edges)``, worked out once per graph shape and node."""
        plans = self._by_edges.get(edges)
        if plans is None:
            if len(self._by_edges) >= self._size:
                del self._by_edges[next(iter(self._by_edges))]  # the oldest shape
            plans = self._by_edges[edges] = {}
        found = plans.get(node)
        if found is None:
            found = plans[node] = intervention_plan(node, edges)
        return found


def intervene(values: dict[str, object], plan: Plan, node: str, x: float) -> None:
    """``do(node = x)`` in place: set it and recompute its descendants by their rules."""
    values[node] = x
    for child, compute in plan:
        values[child] = compute(values)


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Node:
    id: str
    kind: str
    label: str
    p: float
    value: float | str
    unit: str | None = None
    entity: str | None = None


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Edge:
    parent: str
    child: str
    p: float
    rule: str


@dataclass(frozen=True, slots=True)
class BeliefGraph:
    nodes: tuple[Node, ...]
    edges: tuple[Edge, ...]

    def values(self) -> dict[str, float | str]:
        """Node id -> value, what the policy reads."""
        return {n.id: n.value for n in self.nodes}


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-x))


def _lateral_conflict(rx: float, ry: float, vy: float, horizon: float) -> float:
    """How close the entity comes to the robot's path line while the robot arrives."""
    t_reach = max(0.0, rx) / CRUISE_MPS
    t0, t1 = max(0.0, t_reach - 1.5), min(horizon, t_reach + 1.5)
    y0, y1 = ry + vy * t0, ry + vy * t1
    y_min = 0.0 if y0 * y1 <= 0.0 else min(abs(y0), abs(y1))
    y_min = min(y_min, abs(ry))
    g = math.exp(-((y_min / 0.8) ** 2))
    return g * (0.2 if rx < -0.3 else 1.0)


@dataclass(frozen=True, slots=True)
class _Relative:
    """An entity as the robot sees it: position and velocity in the robot frame, and the
    distance as logged (rounded, so that a replay derives the same values)."""

    rx: float
    ry: float
    vx: float
    vy: float
    d: float


def build_belief(
    perception: PerceptionOutput, pose: tuple[float, float, float], speed: float
) -> BeliefGraph:
    """Derive the belief graph from the entity set and the robot's own motion."""
    ox, oy, h = pose
    c, s = math.cos(h), math.sin(h)
    nodes: list[Node] = []
    edges: list[Edge] = []
    distance_ids: set[str] = set()
    for e in perception.entities:
        conf = e.confidence[e.cls]
        nodes.append(Node(e.id, "entity", e.cls, conf, e.cls, None, e.id))
        dx, dy = e.x - ox, e.y - oy
        rx, ry = c * dx + s * dy, -s * dx + c * dy
        vx, vy = c * e.vx + s * e.vy, -s * e.vx + c * e.vy
        if math.hypot(vx, vy) < STATIONARY_MPS:
            # Below this the track's velocity is centroid jitter (the visible face shifts as
            # the robot passes), not motion: predict the entity as standing still.
            vx = vy = 0.0
        d = math.hypot(rx, ry)
        p_d = _distance_confidence(e)
        did = f"{e.id}.distance"
        distance_ids.add(did)
        d = round(d, 3)  # derived values follow from the logged value, so a replay agrees
        nodes.append(Node(did, "state", "distance", p_d, d, "m"))
        edges.append(Edge(e.id, did, p_d, RULE_RANGE))
        seen = _Relative(rx, ry, vx, vy, d)
        if e.cls == "person":
            _person_beliefs(e.id, seen, conf=conf, p_d=p_d, nodes=nodes, edges=edges)
        elif e.cls == "forklift":
            _vehicle_beliefs(e.id, seen, speed, conf=conf, p_d=p_d, nodes=nodes, edges=edges)
    _corridor_beliefs(perception, distance_ids, nodes, edges)
    return BeliefGraph(tuple(nodes), tuple(edges))


def _intent(vx: float, vy: float) -> tuple[str, float]:
    """A pedestrian's intent from its velocity in the robot frame, and how sure it is."""
    speed_e = math.hypot(vx, vy)
    if speed_e < 0.25:
        intent, p_i = "standing", 0.9
    elif abs(vy) > abs(vx):
        intent, p_i = "crossing", min(0.95, 0.5 + speed_e / 2)
    elif vx < 0:
        intent, p_i = "approaching", min(0.95, 0.5 + speed_e / 2)
    else:
        intent, p_i = "leaving", min(0.95, 0.5 + speed_e / 2)
    return intent, round(p_i, 3)


def _person_beliefs(
    eid: str, seen: _Relative, *, conf: float, p_d: float, nodes: list[Node], edges: list[Edge]
) -> None:
    """A person's intent, path conflict and collision risk, appended to the graph."""
    did = f"{eid}.distance"
    intent, p_i = _intent(seen.vx, seen.vy)
    iid, rid = f"{eid}.intent", f"{eid}.collision_risk"
    nodes.append(Node(iid, "state", "pedestrian intent", p_i, intent))
    edges.append(Edge(eid, iid, p_i, RULE_INTENT))
    cid = f"{eid}.conflict"
    g = round(_lateral_conflict(seen.rx, seen.ry, seen.vy, 6.0), 3)
    nodes.append(Node(cid, "state", "path conflict", p_d, g))
    edges.append(Edge(eid, cid, p_d, RULE_PED_CONFLICT))
    risk = ped_risk(seen.d, intent, g)
    p_r = round(conf * p_d, 3)
    nodes.append(Node(rid, "state", "collision risk", p_r, risk))
    edges.append(Edge(did, rid, p_d, RULE_PED_RISK))
    edges.append(Edge(iid, rid, p_i, RULE_PED_RISK))
    edges.append(Edge(cid, rid, p_d, RULE_PED_RISK))


def _vehicle_beliefs(
    eid: str,
    seen: _Relative,
    speed: float,
    *,
    conf: float,
    p_d: float,
    nodes: list[Node],
    edges: list[Edge],
) -> None:
    """A vehicle's closing speed, time to collision, path conflict and collision risk."""
    rx, ry, vx, vy, d = seen.rx, seen.ry, seen.vx, seen.vy, seen.d
    did = f"{eid}.distance"
    rel_vx = vx - speed
    closing = round(-(rel_vx * rx + vy * ry) / max(d, 1e-6), 3)
    kid, tid = f"{eid}.closing", f"{eid}.ttc"
    cid, rid = f"{eid}.conflict", f"{eid}.collision_risk"
    nodes.append(Node(kid, "state", "closing speed", p_d, closing, "m/s"))
    edges.append(Edge(eid, kid, p_d, RULE_CLOSING))
    ttc = time_to_collision(d, closing)
    nodes.append(Node(tid, "state", "time to collision", p_d, ttc, "s"))
    edges.append(Edge(did, tid, p_d, RULE_TTC))
    edges.append(Edge(kid, tid, p_d, RULE_TTC))
    y_pred = ry + vy * min(ttc, 5.0)
    # Miss distance beyond the robot's half width (the track is the near face).
    miss = max(0.0, min(abs(ry), abs(y_pred)) - 0.35)
    # A vehicle standing still is an obstacle (see aisle_blocked), not on a course.
    # Perception reports zero velocity until a track's motion is confirmed, so a
    # vehicle whose motion is unknown is never taken to be moving.
    moving = 1.0 if math.hypot(vx, vy) >= VEHICLE_MOVING_MPS else 0.0
    g = round(moving * math.exp(-((miss / 0.5) ** 2)), 3)
    nodes.append(Node(cid, "state", "path conflict", p_d, g))
    edges.append(Edge(eid, cid, p_d, RULE_VEH_CONFLICT))
    risk = vehicle_risk(ttc, g)
    p_r = round(conf * p_d, 3)
    nodes.append(Node(rid, "state", "collision risk", p_r, risk))
    edges.append(Edge(tid, rid, p_d, RULE_VEH_RISK))
    edges.append(Edge(cid, rid, p_d, RULE_VEH_RISK))


def _corridor_beliefs(
    perception: PerceptionOutput, distance_ids: set[str], nodes: list[Node], edges: list[Edge]
) -> None:
    """The corridor's clearance and whether the aisle is blocked (and by whom)."""
    corridor = perception.corridor
    lidar_seen = any(ev.sensor == "lidar" and ev.weight >= 0.5 for ev in corridor.evidence)
    p_c = 0.97 if lidar_seen else 0.8
    nodes.append(Node("corridor", "entity", "corridor", p_c, "corridor", None, "corridor"))
    clearance = round(min(corridor.clearance, CORRIDOR_MAX_M), 3)
    nodes.append(Node("corridor.clearance", "state", "corridor clearance", p_c, clearance, "m"))
    edges.append(Edge("corridor", "corridor.clearance", p_c, RULE_CLEARANCE))
    blocked = p_blocked(clearance)
    nodes.append(Node("aisle_blocked", "state", "aisle blocked", blocked, blocked))
    edges.append(Edge("corridor.clearance", "aisle_blocked", p_c, RULE_BLOCKED))
    if corridor.blocker is not None and f"{corridor.blocker}.distance" in distance_ids:
        edges.append(Edge(f"{corridor.blocker}.distance", "aisle_blocked", p_c, RULE_OBSTACLE))


def _distance_confidence(e: PerceivedEntity) -> float:
    sensors = {ev.sensor for ev in e.evidence}
    if not e.observed:
        return 0.8
    if "lidar" in sensors:
        return 0.97
    return 0.85
