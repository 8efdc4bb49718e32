"""Layer 2: the belief graph. Entity nodes, derived states, and edges with P(child | parent).

Node ids are stable and readable; the investigator and the metrics rely on them:

- ``<entity>`` (kind ``entity``, ``entity=<perception entity id>``, value = its class)
- ``<entity>.distance`` (m), parent ``<entity>``
- ``<entity>.intent`` (person: standing | crossing | approaching | leaving), parent ``<entity>``
- ``<entity>.ttc`` (forklift, s, 99 = not closing), parent ``<entity>.distance``
- ``<entity>.collision_risk`` in [0, 1]; person: parents ``.distance`` and ``.intent``;
  forklift: parent ``.ttc``
- ``corridor`` (entity), ``corridor.clearance`` (m), ``aisle_blocked`` (P(blocked)), parent
  ``corridor.clearance`` and, when an obstacle bounds the clearance, ``<obstacle>.distance``
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.perception import CORRIDOR_MAX_M, PerceivedEntity, PerceptionOutput

CRUISE_MPS = 1.2
TTC_CAP_S = 99.0
STATIONARY_MPS = 0.3
VEHICLE_MOVING_MPS = 0.5
_INTENT_WEIGHT = {"standing": 0.85, "crossing": 1.0, "approaching": 1.0, "leaving": 0.6}

RULE_RANGE = "range: |entity - robot| from the fused track position"
RULE_INTENT = "intent: entity velocity relative to the robot's heading"
RULE_PED_RISK = (
    "risk = lateral conflict (path occupancy while the robot arrives at cruise) "
    "x proximity sigmoid((4.0 m - distance) / 1.2 m) x intent weight"
)
RULE_TTC = "ttc = distance / closing speed (99 s when not closing)"
RULE_VEH_RISK = (
    "risk = lateral conflict x sigmoid((4.5 s - ttc) / 1.0 s); 0 unless the vehicle is seen "
    "moving at 0.5 m/s or more"
)
RULE_CLEARANCE = "clearance = nearest non-person LiDAR return inside the corridor"
RULE_BLOCKED = "P(blocked) = sigmoid((4.0 m - clearance) / 0.5 m)"
RULE_OBSTACLE = "obstacle bounds the corridor clearance"


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
        nodes.append(Node(did, "state", "distance", p_d, round(d, 3), "m"))
        edges.append(Edge(e.id, did, p_d, RULE_RANGE))
        if e.cls == "person":
            speed_e = math.hypot(vx, vy)
            if speed_e < 0.25:
                intent, p_i = "standing", 0.9
            elif abs(vy) > abs(vx):
                intent, p_i = "crossing", min(0.95, 0.5 + speed_e / 2)
            elif vx < 0:
                intent, p_i = "approaching", min(0.95, 0.5 + speed_e / 2)
            else:
                intent, p_i = "leaving", min(0.95, 0.5 + speed_e / 2)
            p_i = round(p_i, 3)
            iid, rid = f"{e.id}.intent", f"{e.id}.collision_risk"
            nodes.append(Node(iid, "state", "pedestrian intent", p_i, intent))
            edges.append(Edge(e.id, iid, p_i, RULE_INTENT))
            g = _lateral_conflict(rx, ry, vy, 6.0)
            prox = _sigmoid((4.0 - d) / 1.2)
            risk = round(g * prox * _INTENT_WEIGHT[intent], 3)
            p_r = round(conf * p_d, 3)
            nodes.append(Node(rid, "state", "collision risk", p_r, risk))
            edges.append(Edge(did, rid, p_d, RULE_PED_RISK))
            edges.append(Edge(iid, rid, p_i, RULE_PED_RISK))
        elif e.cls == "forklift":
            rel_vx = vx - speed
            closing = -(rel_vx * rx + vy * ry) / max(d, 1e-6)
            ttc = min(TTC_CAP_S, d / closing) if closing > 0.05 else TTC_CAP_S
            ttc = round(ttc, 3)
            tid, rid = f"{e.id}.ttc", f"{e.id}.collision_risk"
            nodes.append(Node(tid, "state", "time to collision", p_d, ttc, "s"))
            edges.append(Edge(did, tid, p_d, RULE_TTC))
            y_pred = ry + vy * min(ttc, 5.0)
            # Miss distance beyond the robot's half width (the track is the near face).
            miss = max(0.0, min(abs(ry), abs(y_pred)) - 0.35)
            g = math.exp(-((miss / 0.5) ** 2))
            # A vehicle standing still is an obstacle (see aisle_blocked), not on a course.
            # Perception reports zero velocity until a track's motion is confirmed, so a
            # vehicle whose motion is unknown is never taken to be moving.
            moving = 1.0 if math.hypot(vx, vy) >= VEHICLE_MOVING_MPS else 0.0
            risk = round(moving * g * _sigmoid((4.5 - ttc) / 1.0), 3)
            p_r = round(conf * p_d, 3)
            nodes.append(Node(rid, "state", "collision risk", p_r, risk))
            edges.append(Edge(tid, rid, p_d, RULE_VEH_RISK))

    corridor = perception.corridor
    lidar_seen = any(ev.sensor == "lidar" and ev.weight >= 0.5 for ev in corridor.evidence)
    p_c = 0.97 if lidar_seen else 0.8
    nodes.append(Node("corridor", "entity", "corridor", p_c, "corridor", None, "corridor"))
    clearance = round(min(corridor.clearance, CORRIDOR_MAX_M), 3)
    nodes.append(Node("corridor.clearance", "state", "corridor clearance", p_c, clearance, "m"))
    edges.append(Edge("corridor", "corridor.clearance", p_c, RULE_CLEARANCE))
    blocked = round(_sigmoid((4.0 - clearance) / 0.5), 3)
    nodes.append(Node("aisle_blocked", "state", "aisle blocked", blocked, blocked))
    edges.append(Edge("corridor.clearance", "aisle_blocked", p_c, RULE_BLOCKED))
    if corridor.blocker is not None and f"{corridor.blocker}.distance" in distance_ids:
        edges.append(Edge(f"{corridor.blocker}.distance", "aisle_blocked", p_c, RULE_OBSTACLE))
    return BeliefGraph(tuple(nodes), tuple(edges))


def _distance_confidence(e: PerceivedEntity) -> float:
    sensors = {ev.sensor for ev in e.evidence}
    if not e.observed:
        return 0.8
    if "lidar" in sensors:
        return 0.97
    return 0.85
