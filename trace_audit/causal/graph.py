"""The causal graph and the counterfactual tree of one decision, as graphs.

``causal_graph`` rebuilds the decision's causal graph from the chains that
``trace_audit.chains`` walked: sensor reading -> evidence -> perception entity -> belief
nodes -> factor -> action, one edge per level of each factor's chain. A level the log does
not document is still an edge, marked ``documented=False`` and drawn from a placeholder node
(``missing=True``) when there is nothing logged to draw it from: a gap is shown, never
skipped. ``tree_graph`` rebuilds the counterfactual decision tree with the taken path marked.
Each has a ``*_data`` twin that returns plain JSON data without importing networkx.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from itertools import pairwise
from typing import TYPE_CHECKING, Required, TypedDict, Unpack

from trace_audit.causal.decision import Decision, TreeView, format_value, read_decision
from trace_audit.causal.defaults import layer_with_defaults
from trace_audit.causal.lenient import as_list, as_mapping, as_str, mappings
from trace_audit.chains import DecisionChains, FactorChain, Link
from trace_audit.log_time import SECONDS_CLOCK, LogClock
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.records import TOPIC_BELIEF, TOPIC_PERCEPTION

if TYPE_CHECKING:  # networkx is imported by the two functions that return its graphs
    import networkx as nx

__all__ = [
    "ACTION_NODE",
    "EdgeData",
    "GraphAttributes",
    "GraphData",
    "NodeData",
    "causal_graph",
    "causal_graph_data",
    "graph_data",
    "tree_graph",
    "tree_graph_data",
]

ACTION_NODE = "action"


class GraphAttributes(TypedDict, total=False):
    """The graph's own attributes: the causal graph's decision (``cycle``, ``t_ns``,
    ``command``), the tree's ``root`` and ``taken_path``."""

    cycle: int
    t_ns: int
    command: str | None
    root: str | None
    taken_path: list[str]


class NodeAttributes(TypedDict, total=False):
    """A node's attributes. Causal graph: ``kind`` (sensor, evidence, entity, belief,
    action, missing), ``label``, ``missing``, ``detail`` (why a placeholder), ``factor``,
    ``belief_kind`` and ``p`` (as logged: untrusted JSON), ``belief_id``, ``entity_id``,
    ``in_cycle``. Tree: ``label``, ``test``, ``command``, ``taken``, ``missing``."""

    kind: str
    label: str
    missing: bool
    detail: str
    factor: bool
    belief_kind: object
    p: object
    belief_id: str
    entity_id: str
    in_cycle: bool
    test: str | None
    command: str | None
    taken: bool


class EdgeAttributes(TypedDict, total=False):
    """An edge's attributes. Causal graph: ``level``, ``documented``, ``detail``,
    ``factors`` (the factor chains that use it), ``role``, and a belief edge's ``rule``
    and ``p`` (as logged: untrusted JSON). Tree: ``label``, ``taken``."""

    level: str
    documented: bool
    detail: str
    factors: list[str]
    role: str
    rule: object
    p: object
    label: str
    taken: bool
    unknown: bool
    """Set (True) on a link not documented only because the external recording holding
    the reading could not be read: unknown, not missing."""


class _ChainEdgeAttributes(TypedDict, total=False):
    """What an edge of the causal graph adds to those its chain's link gives it."""

    role: str
    rule: object
    p: object


class NodeData(NodeAttributes, total=False):
    """A node as plain JSON data: its ``id`` and attributes."""

    id: Required[str]


class EdgeData(EdgeAttributes, total=False):
    """An edge as plain JSON data: ``source``, ``target`` and attributes."""

    source: Required[str]
    target: Required[str]


class GraphData(TypedDict):
    """A graph as plain JSON data (``graph_data``): its attributes, nodes and edges."""

    graph: GraphAttributes
    nodes: list[NodeData]
    edges: list[EdgeData]


class _Graph:
    """A directed graph with attributes, as small as the builders below need.

    ``explain`` builds its graphs here and hands out plain data (``graph_data``), so it
    does not import networkx (~50-120 ms of a ~0.3 s command: its ``__init__`` imports every
    algorithm). Nodes and edges iterate in networkx's order (nodes as added; edges by source
    node in that order, then by target as added), so the data is the same as from a
    ``networkx.DiGraph`` built by the same calls."""

    def __init__(self, **graph: Unpack[GraphAttributes]) -> None:
        self.graph = graph
        self.nodes: dict[str, NodeAttributes] = {}
        self._succ: dict[str, dict[str, EdgeAttributes]] = {}

    def __contains__(self, node: str) -> bool:
        return node in self.nodes

    def add_node(self, node: str, **attrs: Unpack[NodeAttributes]) -> None:
        self.nodes.setdefault(node, {}).update(attrs)

    def add_edge(self, u: str, v: str, **attrs: Unpack[EdgeAttributes]) -> None:
        for end in (u, v):
            self.nodes.setdefault(end, {})
        self._succ.setdefault(u, {}).setdefault(v, {}).update(attrs)

    def edge(self, u: str, v: str) -> EdgeAttributes | None:
        """The attributes of edge ``u -> v`` (None when there is no such edge)."""
        return self._succ.get(u, {}).get(v)

    def edges(self) -> Iterable[tuple[str, str, EdgeAttributes]]:
        for u in self.nodes:
            for v, data in self._succ.get(u, {}).items():
                yield u, v, data

    def data(self) -> GraphData:
        return {
            "graph": self.graph.copy(),
            "nodes": [{"id": n, **attrs} for n, attrs in self.nodes.items()],
            "edges": [{"source": u, "target": v, **attrs} for u, v, attrs in self.edges()],
        }

    def to_networkx(self) -> nx.DiGraph:
        import networkx as nx  # only callers that want a DiGraph pay for its import

        g = nx.DiGraph(**self.graph)
        g.add_nodes_from(self.nodes.items())
        g.add_edges_from(self.edges())
        return g


def causal_graph(
    cycle: Cycle,
    chains: DecisionChains,
    decision: Decision | None = None,
    clock: LogClock = SECONDS_CLOCK,
) -> nx.DiGraph:
    """The decision's causal graph: evidence -> entity -> belief nodes -> factor -> action.

    Node attributes: ``kind`` (sensor, evidence, entity, belief, action), ``label``,
    ``missing`` (a placeholder for something the log does not hold). Edge attributes:
    ``level`` (the chain level it documents), ``documented``, ``detail``, ``factors`` (which
    factor chains use it) and, for belief edges, ``rule`` and ``p``. A sensor reading's time
    is shown in ``clock`` (the log's ``LogClock``: ISO on a wall clock).
    """
    return _causal(cycle, chains, decision, clock).to_networkx()


def causal_graph_data(
    cycle: Cycle,
    chains: DecisionChains,
    decision: Decision | None = None,
    clock: LogClock = SECONDS_CLOCK,
) -> GraphData:
    """``graph_data(causal_graph(...))``, built without networkx."""
    return _causal(cycle, chains, decision, clock).data()


def _causal(
    cycle: Cycle, chains: DecisionChains, decision: Decision | None, clock: LogClock
) -> _Graph:
    decision = decision or read_decision(cycle)
    belief = as_mapping(layer_with_defaults(cycle, TOPIC_BELIEF)) or {}
    perception = as_mapping(layer_with_defaults(cycle, TOPIC_PERCEPTION)) or {}
    nodes = {str(n.get("id")): n for n in mappings(belief.get("nodes"))}
    edges = {(str(e.get("parent")), str(e.get("child"))): e for e in mappings(belief.get("edges"))}
    entities = {str(e.get("id")): e for e in mappings(perception.get("entities"))}
    sensors = {(m.topic, m.log_time_ns) for m in cycle.sensors}

    g = _Graph(cycle=cycle.cycle, t_ns=cycle.t_ns, command=decision.command)
    g.add_node(
        ACTION_NODE,
        kind="action",
        label=decision.command or "? (action not logged)",
        missing=decision.command is None,
    )
    builder = _GraphBuilder(g, nodes, edges, entities, sensors, clock=clock)
    for chain in chains.factors:
        builder.add_chain(chain)
    return g


class _GraphBuilder:
    def __init__(
        self,
        g: _Graph,
        nodes: Mapping[str, Mapping[str, object]],
        edges: Mapping[tuple[str, str], Mapping[str, object]],
        entities: Mapping[str, Mapping[str, object]],
        sensors: set[tuple[str, int]],
        *,
        clock: LogClock,
    ) -> None:
        self.g = g
        self.nodes = nodes
        self.edges = edges
        self.entities = entities
        self.sensors = sensors
        self.clock = clock

    def _node(self, node_id: str, **attrs: Unpack[NodeAttributes]) -> str:
        if node_id not in self.g:
            self.g.add_node(node_id, **attrs)
        return node_id

    def _placeholder(self, level: str, link: Link, above: str) -> str:
        """A node for what the log does not document at ``level`` below node ``above``.

        Keyed by where it attaches, so factor chains that break at the same place share it.
        """
        what = {
            "belief_path": "entity node",
            "entity": "perception entity",
            "evidence_ref": "evidence",
            "sensor_reading": "sensor reading",
        }.get(level, level)
        return self._node(
            f"missing:{level}:{above}",
            kind="missing",
            missing=True,
            label=f"? {what} (not documented)",
            detail=link.detail,
        )

    def _edge(
        self,
        u: str,
        v: str,
        chain: FactorChain,
        link: Link,
        **attrs: Unpack[_ChainEdgeAttributes],
    ) -> None:
        data = self.g.edge(u, v)
        if data is not None:
            data["documented"] = data["documented"] or link.documented
            if chain.node not in data["factors"]:
                data["factors"].append(chain.node)
            return
        self.g.add_edge(
            u,
            v,
            level=link.level,
            documented=link.documented,
            detail=link.detail,
            factors=[chain.node],
            **attrs,
        )
        if link.unknown:
            added = self.g.edge(u, v)
            assert added is not None  # just added
            added["unknown"] = True

    def _belief_node(self, node_id: str) -> str:
        raw = self.nodes.get(node_id)
        if raw is None:
            return self._node(
                f"belief:{node_id}",
                kind="belief",
                missing=True,
                label=f"{node_id} (not in belief graph)",
            )
        value = raw.get("value")
        label = str(raw.get("label") or node_id)
        if raw.get("kind") == "entity":
            # the belief graph's node for a perceived entity: name it by its entity id
            label = f"{label} [{raw.get('entity') or node_id}]"
        elif value is not None:
            label = f"{label} = {format_value(value, as_str(raw.get('unit')))}"
        return self._node(
            f"belief:{node_id}",
            kind="belief",
            missing=False,
            label=label,
            belief_kind=raw.get("kind"),
            p=raw.get("p"),
            belief_id=node_id,
        )

    def add_chain(self, chain: FactorChain) -> None:
        links = {link.level: link for link in chain.links}
        top = self._belief_node(chain.node)
        self.g.nodes[top]["factor"] = True
        self._edge(top, ACTION_NODE, chain, links["factor_node"], role="factor")
        # Belief path: "factor <- parent <- ... <- entity node" when documented.
        below = top
        path_link = links.get("belief_path")
        entity_node: str | None = None
        if self.g.nodes[top].get("belief_kind") == "entity":
            entity_node = chain.node
        elif path_link is not None and path_link.documented:
            path = path_link.ref.split(" <- ")
            for child, parent in pairwise(path):
                raw = self.edges.get((parent, child), {})
                upper = self._belief_node(parent)
                self._edge(upper, below, chain, path_link, rule=raw.get("rule"), p=raw.get("p"))
                below = upper
            entity_node = path[-1]
        elif path_link is not None:
            upper = self._placeholder("belief_path", path_link, below)
            self._edge(upper, below, chain, path_link)
            below = upper
        self._below_entity(chain, links, below, entity_node)

    def _below_entity(
        self, chain: FactorChain, links: Mapping[str, Link], below: str, entity_node: str | None
    ) -> None:
        entity_link = links.get("entity")
        if entity_link is None:
            return
        raw_node = self.nodes.get(entity_node or "", {})
        entity_id = as_str(raw_node.get("entity")) if raw_node else None
        entity = self.entities.get(entity_id or "") if entity_link.documented else None
        if entity is not None and entity_id is not None:
            entity_key = self._node(
                f"entity:{entity_id}",
                kind="entity",
                missing=False,
                label=_entity_label(entity_id, entity),
                entity_id=entity_id,
            )
        else:
            entity_key = self._placeholder("entity", entity_link, below)
        self._edge(entity_key, below, chain, entity_link)

        ref_link = links.get("evidence_ref")
        if ref_link is None:
            return
        evidence = list(mappings(entity.get("evidence"))) if entity else []
        chosen = _pick_evidence(evidence, ref_link.ref if ref_link.documented else "")
        if chosen is not None and entity_id is not None:
            index, item = chosen
            evidence_key = self._node(
                f"evidence:{entity_id}:{index}",
                kind="evidence",
                missing=False,
                label=_evidence_label(item),
            )
        else:
            evidence_key = self._placeholder("evidence_ref", ref_link, entity_key)
        self._edge(evidence_key, entity_key, chain, ref_link)

        sensor_link = links.get("sensor_reading")
        if sensor_link is None:
            return
        if ref_link.documented and sensor_link.ref:
            topic, _, when = sensor_link.ref.rpartition("@")
            logged = when.isdigit() and (topic, int(when)) in self.sensors
            sensor_key = self._node(
                f"sensor:{sensor_link.ref}",
                kind="sensor",
                missing=not sensor_link.documented,
                label=f"{topic} @ {self.clock.show(int(when))}"
                if when.isdigit()
                else sensor_link.ref,
                in_cycle=logged,
            )
        else:
            sensor_key = self._placeholder("sensor_reading", sensor_link, evidence_key)
        self._edge(sensor_key, evidence_key, chain, sensor_link)


def _pick_evidence(
    evidence: list[Mapping[str, object]], ref_label: str
) -> tuple[int, Mapping[str, object]] | None:
    """The evidence item whose ref the chain followed, else the first item logged."""
    for index, item in enumerate(evidence):
        ref = as_mapping(item.get("ref"))
        if ref and f"{ref.get('topic')}@{ref.get('log_time_ns')}" == ref_label:
            return index, item
    return (0, evidence[0]) if evidence else None


def _entity_label(entity_id: str, entity: Mapping[str, object]) -> str:
    cls = as_str(entity.get("class")) or "?"
    confidence = as_mapping(entity.get("confidence")) or {}
    p = confidence.get(cls)
    shown = f" {p:.2f}" if isinstance(p, int | float) else ""
    return f"{cls}{shown} ({entity_id})"


def _evidence_label(item: Mapping[str, object]) -> str:
    sensor = as_str(item.get("sensor")) or "?"
    region = as_mapping(item.get("region"))
    where = ""
    if region:
        values = ", ".join(
            f"{v:g}" if isinstance(v, int | float) else str(v)
            for v in as_list(region.get("values"))
        )
        where = f" {region.get('kind')} [{values}]"
    weight = item.get("weight")
    w = f" w={weight:.2f}" if isinstance(weight, int | float) else ""
    return f"{sensor}{where}{w}"


def tree_graph(tree: TreeView) -> nx.DiGraph:
    """The counterfactual decision tree as a DiGraph; ``taken`` marks the chosen path."""
    return _tree(tree).to_networkx()


def tree_graph_data(tree: TreeView) -> GraphData:
    """``graph_data(tree_graph(tree))``, built without networkx."""
    return _tree(tree).data()


def _tree(tree: TreeView) -> _Graph:
    g = _Graph(root=tree.root, taken_path=list(tree.taken_path))
    for node in tree.nodes:
        g.add_node(
            node.id, label=node.label, test=node.test, command=node.command, taken=node.taken
        )
    for edge in tree.edges:
        for end in (edge.parent, edge.child):
            if end not in g:
                g.add_node(
                    end, label=f"? {end}", test=None, command=None, taken=False, missing=True
                )
        g.add_edge(edge.parent, edge.child, label=edge.label, taken=edge.taken)
    return g


def graph_data(g: nx.DiGraph) -> GraphData:
    """A graph as plain JSON data: ``{"graph": {...}, "nodes": [...], "edges": [...]}``."""
    # networkx is untyped: its attribute dicts hold what the builder set, for this module's
    # graphs the attributes above. ``_Graph`` iterates in networkx's order (see there).
    out = _Graph(**g.graph)
    out.nodes = dict(g.nodes(data=True))
    for u, v, data in g.edges(data=True):
        out.add_edge(u, v, **data)
    return out.data()
