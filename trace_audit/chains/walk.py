"""The walk: each factor the action names followed down through the belief graph, the
perception entity and its evidence to a logged sensor reading (``trace_layers``, with every
link; ``score_layers``, the depths alone, for metrics over long logs). The rules it follows
are the package's (``trace_audit.chains``)."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping

from trace_audit.chains.model import (
    EXPECTED_DEPTH_ENTITY,
    EXPECTED_DEPTH_STATE,
    LEVELS,
    DecisionChains,
    DecisionScore,
    FactorChain,
    Link,
)
from trace_audit.sensor_window import SensorWindow
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import TOPIC_ACTION, TOPIC_BELIEF, TOPIC_PERCEPTION

__all__ = ["score_layers", "trace_cycle", "trace_layers"]

_NOT_REACHED = "not reached: the chain is broken above"


def trace_cycle(
    cycle: Cycle, window: SensorWindow | None = None, *, recordings: Recordings | None = None
) -> DecisionChains:
    """The factor chains of one cycle; ``window`` must already hold this cycle's sensors.

    Without a window, refs resolve against this cycle's own sensor messages only (and refs
    into external recordings against ``recordings``).
    """
    if window is None:
        window = SensorWindow(0, recordings)
        window.push(cycle.sensors)
    return trace_layers(
        cycle.cycle,
        cycle.t_ns,
        cycle.layer(TOPIC_ACTION),
        cycle.layer(TOPIC_BELIEF),
        cycle.layer(TOPIC_PERCEPTION),
        window=window,
    )


def trace_layers(
    cycle: int,
    t_ns: int,
    action: object,
    belief: object,
    perception: object,
    *,
    window: SensorWindow,
) -> DecisionChains:
    """The factor chains of one decision given its layer messages as parsed JSON (or a
    metrics shape's fields of them); anything but a JSON object is a layer not logged."""
    if not isinstance(action, dict):
        return DecisionChains(cycle, t_ns, (), 0.0, 0.0, "action not logged")
    rationale = action.get("rationale")
    raw_factors = rationale.get("factors") if isinstance(rationale, dict) else None
    if not raw_factors or not isinstance(raw_factors, list):
        return DecisionChains(cycle, t_ns, (), 0.0, 0.0, "action names no factors")
    walker = _Walker(belief, perception, window)
    chains = tuple(walker.factor(f) for f in raw_factors if isinstance(f, dict))
    if not chains:
        return DecisionChains(cycle, t_ns, (), 0.0, 0.0, "action names no factors")
    n = len(chains)
    et = sum(1 for c in chains if c.depth == c.expected_depth) / n
    et_partial = sum(c.depth / c.expected_depth for c in chains) / n
    return DecisionChains(cycle, t_ns, chains, et, et_partial)


def score_layers(
    action: object, belief: object, perception: object, *, window: SensorWindow
) -> DecisionScore:
    """ET and ET_partial of one decision, as ``trace_layers`` gives them, without the links.

    The fast path for metrics over long logs: same walk, same depths, no link objects.
    """
    if not isinstance(action, dict):
        return DecisionScore(0.0, 0.0, 0, 0, "action not logged")
    rationale = action.get("rationale")
    raw_factors = rationale.get("factors") if type(rationale) is dict else None
    if not raw_factors or type(raw_factors) is not list:
        return DecisionScore(0.0, 0.0, 0, 0, "action names no factors")
    walker = _Walker(belief, perception, window)
    n = traceable = unknown = 0
    partial = 0.0
    for factor in raw_factors:
        if type(factor) is dict:
            depth, expected, not_known = walker.depth(factor)
            n += 1
            traceable += depth == expected
            partial += depth / expected
            unknown += not_known
    if not n:
        return DecisionScore(0.0, 0.0, 0, 0, "action names no factors")
    return DecisionScore(traceable / n, partial / n, n, traceable, "", unknown)


class _Walker:
    """Per-cycle lookups built once and shared by every factor of the decision."""

    __slots__ = (
        "_belief_missing",
        "_depth_memo",
        "_entities",
        "_entity_memo",
        "_nodes",
        "_parents",
        "_perception",
        "_perception_missing",
        "_unknown",
        "_window",
    )

    def __init__(
        self,
        belief: object,
        perception: object,
        window: SensorWindow,
    ) -> None:
        self._window = window
        self._belief_missing = type(belief) is not dict
        self._perception_missing = type(perception) is not dict
        self._perception = perception
        self._nodes: dict[str, dict[str, object]] = {}
        self._parents: dict[str, list[str]] = {}
        if type(belief) is dict:
            self._nodes, self._parents = _index_belief(belief)
        self._entities: dict[str, dict[str, object]] | None = None
        self._entity_memo: dict[str, tuple[Link, ...]] = {}
        self._depth_memo: dict[str, int] = {}
        # entities whose refs do not resolve but one lies in a recording not read
        self._unknown: set[str] = set()

    def _entity(self, entity_id: str) -> dict[str, object] | None:
        entities = self._entities
        if entities is None:
            entities = self._entities = {}
            perception = self._perception
            if type(perception) is dict:
                for entity in _dicts(perception.get("entities")):
                    key = entity.get("id")
                    if type(key) is str:
                        entities[key] = entity
        return entities.get(entity_id)

    def depth(self, factor: dict[str, object]) -> tuple[int, int, bool]:
        """(documented depth, expected depth, unknown) of a factor: ``factor()`` without the
        links; unknown when the chain stops only at a reading in a recording not read."""
        nodes = self._nodes
        start = factor.get("node")
        if type(start) is not str:
            return 0, EXPECTED_DEPTH_STATE, False
        node = nodes.get(start)
        if node is None:
            return 0, EXPECTED_DEPTH_STATE, False
        if node.get("kind") == "entity":
            below = self._entity_depth(node)
            return (
                1 + below,
                EXPECTED_DEPTH_ENTITY,
                below == 2 and node.get("entity") in self._unknown,
            )
        parents = self._parents
        best = -1
        unknown = False
        seen = {start}
        frontier: list[str] = [start]
        while frontier:
            upper: list[str] = []
            for child in frontier:
                for parent in parents.get(child, ()):
                    if parent in seen:
                        continue
                    seen.add(parent)
                    above = nodes.get(parent)
                    if above is None:
                        continue
                    if above.get("kind") == "entity":
                        found = self._entity_depth(above)
                        if found == 3:
                            return EXPECTED_DEPTH_STATE, EXPECTED_DEPTH_STATE, False
                        best = max(best, found)
                        unknown = unknown or above.get("entity") in self._unknown
                    else:
                        upper.append(parent)
            frontier = upper
        if best < 0:
            return 1, EXPECTED_DEPTH_STATE, False
        return 2 + best, EXPECTED_DEPTH_STATE, unknown and best == 2

    def _entity_depth(self, node: dict[str, object]) -> int:
        """Documented levels below an entity node: entity, evidence_ref, sensor_reading."""
        entity_id = node.get("entity")
        if type(entity_id) is not str or not entity_id:
            return 0
        memo = self._depth_memo.get(entity_id)
        if memo is not None:
            return memo
        entity = self._entity(entity_id)
        if entity is None:
            depth = 0
        else:
            depth = 1
            window = self._window
            unknown = False
            for evidence in _dicts(entity.get("evidence")):
                ref = evidence.get("ref")
                if type(ref) is dict:
                    depth = 2
                    if not window.resolve(ref):
                        depth = 3
                        break
                    unknown = unknown or window.unknown(ref)
            if depth == 2 and unknown:
                self._unknown.add(entity_id)
        self._depth_memo[entity_id] = depth
        return depth

    def factor(self, factor: dict[str, object]) -> FactorChain:
        raw = factor.get("node")
        node_id = raw if type(raw) is str else ""
        name = str(factor.get("name") or "")
        node = self._nodes.get(node_id)
        if node is None:
            why = (
                "belief layer not logged"
                if self._belief_missing
                else f"node {node_id!r} is not in the belief graph"
            )
            links = (
                Link("factor_node", False, node_id, why),
                *(Link(level, False, "", _NOT_REACHED) for level in LEVELS[1:]),
            )
            return FactorChain(node_id, name, links, 0, EXPECTED_DEPTH_STATE)
        top = Link("factor_node", True, node_id)
        if node.get("kind") == "entity":
            below = self._entity_links(node)
            return _chain(node_id, name, (top, *below), EXPECTED_DEPTH_ENTITY)
        reached = self._entity_nodes_above(node_id)
        if not reached:
            links = (
                top,
                Link(
                    "belief_path",
                    False,
                    node_id,
                    f"no documented belief edges lead from {node_id!r} to an entity node",
                ),
                *(Link(level, False, "", _NOT_REACHED) for level in LEVELS[2:]),
            )
            return FactorChain(node_id, name, links, 1, EXPECTED_DEPTH_STATE)
        best: tuple[Link, ...] | None = None
        best_depth = -1
        for path in reached:
            below = self._entity_links(self._nodes[path[-1]])
            depth = _depth(below)
            if depth > best_depth:
                best, best_depth = (Link("belief_path", True, " <- ".join(path)), *below), depth
                if depth == len(below):
                    break
        assert best is not None
        return _chain(node_id, name, (top, *best), EXPECTED_DEPTH_STATE)

    def _entity_nodes_above(self, start: str) -> list[list[str]]:
        """Paths (factor node first) to every entity node reachable through parents, BFS."""
        nodes, parents = self._nodes, self._parents
        seen = {start}
        queue: deque[list[str]] = deque([[start]])
        found: list[list[str]] = []
        while queue:
            path = queue.popleft()
            for parent in parents.get(path[-1], ()):
                if parent in seen:
                    continue
                seen.add(parent)
                node = nodes.get(parent)
                if node is None:
                    continue  # an edge to a node the graph does not hold documents nothing
                step = [*path, parent]
                if node.get("kind") == "entity":
                    found.append(step)
                else:
                    queue.append(step)
        return found

    def _entity_links(self, node: dict[str, object]) -> tuple[Link, ...]:
        """The entity, evidence_ref and sensor_reading links below an entity node."""
        entity_id = node.get("entity")
        if not isinstance(entity_id, str) or not entity_id:
            return (
                Link(
                    "entity",
                    False,
                    str(node.get("id", "")),
                    "entity node names no perception entity",
                ),
                Link("evidence_ref", False, "", _NOT_REACHED),
                Link("sensor_reading", False, "", _NOT_REACHED),
            )
        memo = self._entity_memo.get(entity_id)
        if memo is not None:
            return memo
        links = self._entity_links_uncached(entity_id)
        self._entity_memo[entity_id] = links
        return links

    def _entity_links_uncached(self, entity_id: str) -> tuple[Link, ...]:
        entity = self._entity(entity_id)
        if entity is None:
            why = (
                "perception layer not logged"
                if self._perception_missing
                else f"entity {entity_id!r} is not in this cycle's perception"
            )
            return (
                Link("entity", False, entity_id, why),
                Link("evidence_ref", False, "", _NOT_REACHED),
                Link("sensor_reading", False, "", _NOT_REACHED),
            )
        top = Link("entity", True, entity_id)
        evidence = list(_dicts(entity.get("evidence")))
        refs = [ref for e in evidence if isinstance(ref := e.get("ref"), dict)]
        if not refs:
            why = (
                f"entity {entity_id!r} has no evidence"
                if not evidence
                else f"none of the {len(evidence)} evidence items of {entity_id!r} has a ref"
            )
            return (
                top,
                Link("evidence_ref", False, entity_id, why),
                Link("sensor_reading", False, "", _NOT_REACHED),
            )
        first_why = ""
        unknown = False
        for ref in refs:
            why = self._window.resolve(ref)
            if not why:
                label = _ref_label(ref)
                return (top, Link("evidence_ref", True, label), Link("sensor_reading", True, label))
            first_why = first_why or why
            unknown = unknown or self._window.unknown(ref)
        label = _ref_label(refs[0])
        more = f" (and {len(refs) - 1} other refs)" if len(refs) > 1 else ""
        return (
            top,
            Link("evidence_ref", True, label),
            Link("sensor_reading", False, label, first_why + more, unknown),
        )


def _chain(node: str, name: str, links: tuple[Link, ...], expected: int) -> FactorChain:
    return FactorChain(node, name, links, _depth(links), expected)


def _depth(links: Iterable[Link]) -> int:
    depth = 0
    for link in links:
        if not link.documented:
            break
        depth += 1
    return depth


def _index_belief(
    belief: dict[str, object],
) -> tuple[dict[str, dict[str, object]], dict[str, list[str]]]:
    """Node by id, and the parents of each child, from a belief message's JSON."""
    nodes: dict[str, dict[str, object]] = {}
    parents: dict[str, list[str]] = {}
    raw = belief.get("nodes")
    if type(raw) is list:
        for node in raw:
            if type(node) is dict:
                node_id = node.get("id")
                if type(node_id) is str:
                    nodes[node_id] = node
    raw = belief.get("edges")
    if type(raw) is list:
        for edge in raw:
            if type(edge) is dict:
                parent, child = edge.get("parent"), edge.get("child")
                if type(parent) is str and type(child) is str:
                    found = parents.get(child)
                    if found is None:
                        parents[child] = [parent]
                    else:
                        found.append(parent)
    return nodes, parents


def _dicts(value: object) -> list[dict[str, object]]:
    if type(value) is list:
        return [v for v in value if type(v) is dict]
    return []


def _ref_label(ref: Mapping[str, object]) -> str:
    recording = ref.get("recording")
    where = f"{recording}:" if type(recording) is str else ""
    return f"{where}{ref.get('topic')}@{ref.get('log_time_ns')}"
