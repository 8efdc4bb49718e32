"""One decision as an investigator reads it, and its causal graph and counterfactual tree.

``read_decision`` turns a logged cycle into a ``Decision``: the action, its rationale and
factors, alternatives, counterfactuals, the counterfactual decision tree and the execution
record. It reads the plain JSON of each layer (``Cycle.layer``) and is lenient about missing
fields, so a warm-tier summary or a damaged record still yields what was logged.

``causal_graph`` rebuilds the decision's causal graph from the chains that
``trace_audit.chains`` walked: sensor reading -> evidence -> perception entity -> belief
nodes -> factor -> action, one edge per level of each factor's chain. A level the log does
not document is still an edge, marked ``documented=False`` and drawn from a placeholder node
(``missing=True``) when there is nothing logged to draw it from: a gap is shown, never
skipped. ``tree_graph`` rebuilds the counterfactual decision tree with the taken path marked.
"""

from __future__ import annotations

import types
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import cache
from itertools import pairwise
from typing import TYPE_CHECKING, Any, Union, get_args, get_origin

from pydantic import BaseModel

from trace_audit.chains import DecisionChains, FactorChain, Link
from trace_audit.jsonout import OMIT_EMPTY
from trace_runtime.cycles import Cycle
from trace_runtime.records import (
    MESSAGE_MODELS,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
)

if TYPE_CHECKING:  # networkx is imported by the two functions that return its graphs
    import networkx as nx

__all__ = [
    "ACTION_NODE",
    "AlternativeView",
    "ChannelView",
    "CheckView",
    "CounterfactualView",
    "Decision",
    "ExecutionView",
    "FactorValue",
    "TreeEdgeView",
    "TreeNodeView",
    "TreeView",
    "causal_graph",
    "causal_graph_data",
    "format_value",
    "graph_data",
    "layer_with_defaults",
    "read_decision",
    "split_flags",
    "tree_graph",
    "tree_graph_data",
]

Scalar = float | int | bool | str

ACTION_NODE = "action"


def format_value(value: Any, unit: str | None = None) -> str:
    """A factor value as people read it: ``1.5 m``, ``0.70``, ``true``."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, float):
        text = f"{value:.4g}"
        if "e" not in text and "." not in text and "n" not in text:
            text += ".0"  # a float stays recognisably a float: 2.0 m, not 2 m
        if "e" in text:
            text = f"{value:.1f}" if abs(value) >= 1 else f"{value:.2e}"
    elif value is None:
        text = "?"
    else:
        text = str(value)
    return f"{text} {unit}" if unit else text


# --- the decision ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class FactorValue:
    """A factor the decision depended on, with the value the policy saw."""

    node: str
    name: str
    value: Scalar | None
    unit: str | None = None

    @property
    def label(self) -> str:
        return self.name or self.node

    @property
    def shown(self) -> str:
        return format_value(self.value, self.unit)


@dataclass(frozen=True, slots=True)
class AlternativeView:
    """A command that was considered and lost."""

    command: str
    score: float | None
    rejected_because: str


@dataclass(frozen=True, slots=True)
class CounterfactualView:
    """``would_select`` would have been chosen had the factor satisfied the comparison."""

    factor: str
    name: str
    comparison: str
    threshold: Scalar | None
    would_select: str
    value: Scalar | None
    unit: str | None
    text: str


@dataclass(frozen=True, slots=True)
class CheckView:
    rule: str
    passed: bool
    value: float | None
    limit: float | None
    detail: str


SCENARIO_FLAG = "scenario:"
"""A flag of this form labels the situation (e.g. a test scenario); it reports no problem."""


def split_flags(flags: Iterable[str]) -> tuple[tuple[str, ...], str | None]:
    """(flags that report something, the scenario label if a ``scenario:`` flag names one)."""
    real: list[str] = []
    scenario: str | None = None
    for flag in flags:
        if flag.startswith(SCENARIO_FLAG):
            scenario = scenario or flag[len(SCENARIO_FLAG) :]
        else:
            real.append(flag)
    return tuple(real), scenario


@dataclass(frozen=True, slots=True)
class ChannelView:
    """One logged actuator channel (profile 1.1): its name, unit, intended, actual, deviation."""

    name: str
    unit: str
    intended: float | None
    actual: float | None
    deviation: float | None


_OMIT_EMPTY = {OMIT_EMPTY: True}


@dataclass(frozen=True, slots=True)
class ExecutionView:
    """Layer 4: intended vs actual, deviation, compliance checks and flags.

    ``intended``/``actual`` are the planar motion (linear m/s, angular rad/s), (None, None)
    when the record has none; ``channels`` the named actuator channels of profile 1.1, in
    the robot's own units. ``flags`` are as logged; ``problems`` are those that are not a
    ``scenario:`` label. ``channels`` and ``deviation_unit`` are left out of JSON when a
    record has none, so the JSON of a profile 1.0 log reads exactly as before.
    """

    intended: tuple[float | None, float | None]
    actual: tuple[float | None, float | None]
    deviation: float | None
    checks: tuple[CheckView, ...]
    flags: tuple[str, ...]
    problems: tuple[str, ...]
    scenario: str | None
    channels: tuple[ChannelView, ...] = field(default=(), metadata=_OMIT_EMPTY)
    deviation_unit: str | None = field(default=None, metadata=_OMIT_EMPTY)

    @property
    def planar(self) -> bool:
        """Whether the record logged a planar motion (intended or actual)."""
        return self.intended != (None, None) or self.actual != (None, None)


@dataclass(frozen=True, slots=True)
class TreeNodeView:
    id: str
    label: str
    test: str | None
    command: str | None
    taken: bool


@dataclass(frozen=True, slots=True)
class TreeEdgeView:
    parent: str
    child: str
    label: str
    taken: bool


@dataclass(frozen=True, slots=True)
class TreeView:
    """The counterfactual decision tree with the taken path, and whether it hangs together.

    ``problems`` lists what does not: a taken path that skips an edge, a path that ends
    anywhere but a leaf naming the logged command, an edge to an unknown node.
    """

    nodes: tuple[TreeNodeView, ...]
    edges: tuple[TreeEdgeView, ...]
    taken_path: tuple[str, ...]
    root: str | None
    problems: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Decision:
    """The logged decision of one cycle, layer by layer (None where a layer is absent)."""

    cycle: int
    t_ns: int
    segment: str
    summary: bool
    command: str | None
    parameters: dict[str, float]
    score: float | None
    rationale: str | None
    truncated: bool
    factors: tuple[FactorValue, ...]
    alternatives: tuple[AlternativeView, ...]
    counterfactuals: tuple[CounterfactualView, ...]
    counterfactuals_none_applicable: bool
    tree: TreeView | None
    execution: ExecutionView | None
    layers: tuple[str, ...] = field(default=())

    @property
    def leading(self) -> FactorValue | None:
        """The first factor the rationale names: policies list factors by influence."""
        return self.factors[0] if self.factors else None


# --- schema defaults ----------------------------------------------------------------------


def layer_with_defaults(cycle: Cycle, topic: str) -> Any:
    """``cycle.layer(topic)`` with every optional field the writer left out set to its
    schema default (``trace_runtime.records``), as JSON: a robot in another language may
    omit ``angular`` and mean ``0.0``. A warm summary is returned as kept: a field missing
    there was pruned, not defaulted."""
    layer = cycle.layer(topic)
    model = MESSAGE_MODELS.get(topic)
    if topic not in cycle.payloads or model is None:
        return layer
    return with_defaults(model, layer)


def with_defaults(model: type[BaseModel], value: Any) -> Any:
    """``value`` (plain JSON) with the defaults of ``model``'s omitted optional fields,
    recursively through nested records and lists of them; anything else is left as it is
    (this reads, it does not validate)."""
    if not isinstance(value, Mapping):
        return value
    out = dict(value)
    for key, default, nested in _fields(model):
        if key not in out:
            if default is _REQUIRED:
                continue
            out[key] = default() if callable(default) else default
        if nested is not None:
            item_model, many = nested
            current = out[key]
            if many and isinstance(current, list):
                out[key] = [with_defaults(item_model, item) for item in current]
            elif not many:
                out[key] = with_defaults(item_model, current)
    return out


_REQUIRED = object()


@cache
def _fields(
    model: type[BaseModel],
) -> tuple[tuple[str, Any, tuple[type[BaseModel], bool] | None], ...]:
    """(JSON key, default or a factory or ``_REQUIRED``, nested record type) per field."""
    out = []
    for name, info in model.model_fields.items():
        key = info.alias or name
        if info.is_required():
            default: Any = _REQUIRED
        elif info.default_factory is not None:
            default = info.default_factory
        else:
            default = _jsonable(info.default)
        out.append((key, default, _nested(info.annotation)))
    return tuple(out)


def _jsonable(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _nested(annotation: Any) -> tuple[type[BaseModel], bool] | None:
    """The record type a field holds (and whether it is a list of them), if any."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation, False
    origin = get_origin(annotation)
    if origin is list:
        inner = _nested(get_args(annotation)[0])
        return (inner[0], True) if inner is not None else None
    if origin in (Union, types.UnionType):
        for arg in get_args(annotation):
            found = _nested(arg)
            if found is not None:
                return found
    return None


def read_decision(cycle: Cycle) -> Decision:
    """The decision logged in ``cycle`` (full or warm summary), read leniently, with
    omitted optional fields at their schema defaults."""
    action = _mapping(layer_with_defaults(cycle, TOPIC_ACTION))
    execution = _mapping(layer_with_defaults(cycle, TOPIC_EXECUTION))
    layers = tuple(
        topic
        for topic in (TOPIC_PERCEPTION, TOPIC_BELIEF, TOPIC_ACTION, TOPIC_EXECUTION)
        if topic in cycle.payloads or (cycle.summary and topic in cycle.summary)
    )
    rationale = _mapping(action.get("rationale")) if action else None
    factors = tuple(_factor(f) for f in _dicts(rationale.get("factors") if rationale else None))
    by_node = {f.node: f for f in factors}
    command = _str(action.get("command")) if action else None
    tree = _mapping(action.get("tree")) if action else None
    return Decision(
        cycle=cycle.cycle,
        t_ns=cycle.t_ns,
        segment=cycle.segment,
        summary=cycle.is_summary,
        command=command,
        parameters={
            str(k): float(v)
            for k, v in (_mapping(action.get("parameters")) or {}).items()
            if isinstance(v, int | float) and not isinstance(v, bool)
        }
        if action
        else {},
        score=_num(action.get("score")) if action else None,
        rationale=_str(rationale.get("text")) if rationale else None,
        truncated=bool(rationale.get("truncated")) if rationale else False,
        factors=factors,
        alternatives=tuple(
            AlternativeView(
                _str(a.get("command")) or "?",
                _num(a.get("score")),
                _str(a.get("rejected_because")) or "",
            )
            for a in _dicts(action.get("alternatives") if action else None)
        ),
        counterfactuals=tuple(
            _counterfactual(c, by_node)
            for c in _dicts(action.get("counterfactuals") if action else None)
        ),
        counterfactuals_none_applicable=bool(
            action.get("counterfactuals_none_applicable") if action else False
        ),
        tree=_tree_view(tree, command) if tree else None,
        execution=_execution(execution) if execution else None,
        layers=layers,
    )


def _factor(raw: Mapping[str, Any]) -> FactorValue:
    value = raw.get("value")
    return FactorValue(
        node=_str(raw.get("node")) or "",
        name=_str(raw.get("name")) or "",
        value=value if isinstance(value, int | float | str | bool) else None,
        unit=_str(raw.get("unit")),
    )


def _counterfactual(
    raw: Mapping[str, Any], factors: Mapping[str, FactorValue]
) -> CounterfactualView:
    node = _str(raw.get("factor")) or "?"
    known = factors.get(node)
    name = known.label if known else node
    unit = known.unit if known else None
    comparison = _str(raw.get("comparison")) or "?"
    threshold = raw.get("threshold")
    threshold = threshold if isinstance(threshold, int | float | str | bool) else None
    would = _str(raw.get("would_select")) or "?"
    text = f"would {would} if {name} {comparison} {format_value(threshold, unit)}"
    return CounterfactualView(
        factor=node,
        name=name,
        comparison=comparison,
        threshold=threshold,
        would_select=would,
        value=known.value if known else None,
        unit=unit,
        text=text,
    )


def _execution(raw: Mapping[str, Any]) -> ExecutionView:
    flags = tuple(str(f) for f in raw.get("flags") or () if isinstance(f, str))
    problems, scenario = split_flags(flags)
    intended = _mapping(raw.get("intended")) or {}
    actual = _mapping(raw.get("actual")) or {}
    return ExecutionView(
        intended=(_num(intended.get("linear")), _num(intended.get("angular"))),
        actual=(_num(actual.get("linear")), _num(actual.get("angular"))),
        deviation=_num(raw.get("deviation")),
        checks=tuple(
            CheckView(
                rule=_str(c.get("rule")) or "?",
                passed=bool(c.get("passed")),
                value=_num(c.get("value")),
                limit=_num(c.get("limit")),
                detail=_str(c.get("detail")) or "",
            )
            for c in _dicts(raw.get("checks"))
        ),
        flags=flags,
        problems=problems,
        scenario=scenario,
        channels=tuple(
            ChannelView(
                name=_str(c.get("name")) or "?",
                unit=_str(c.get("unit")) or "",
                intended=_num(c.get("intended")),
                actual=_num(c.get("actual")),
                deviation=_num(c.get("deviation")),
            )
            for c in _dicts(raw.get("channels"))
        ),
        deviation_unit=_str(raw.get("deviation_unit")),
    )


def _tree_view(raw: Mapping[str, Any], command: str | None) -> TreeView:
    path = tuple(str(p) for p in raw.get("taken_path") or () if isinstance(p, str))
    on_path = set(path)
    taken_edges = set(pairwise(path))
    nodes = tuple(
        TreeNodeView(
            id=_str(n.get("id")) or "?",
            label=_str(n.get("label")) or "",
            test=_str(n.get("test")),
            command=_str(n.get("command")),
            taken=n.get("id") in on_path,
        )
        for n in _dicts(raw.get("nodes"))
    )
    edges = tuple(
        TreeEdgeView(
            parent=_str(e.get("parent")) or "?",
            child=_str(e.get("child")) or "?",
            label=_str(e.get("label")) or "",
            taken=(e.get("parent"), e.get("child")) in taken_edges,
        )
        for e in _dicts(raw.get("edges"))
    )
    ids = {n.id for n in nodes}
    children = {e.child for e in edges}
    problems: list[str] = []
    for edge in edges:
        for end in (edge.parent, edge.child):
            if end not in ids:
                problems.append(f"edge {edge.parent} -> {edge.child} names unknown node {end!r}")
    edge_set = {(e.parent, e.child) for e in edges}
    for parent, child in taken_edges:
        if (parent, child) not in edge_set:
            problems.append(f"taken path steps {parent} -> {child}, which is not a tree edge")
    roots = [n.id for n in nodes if n.id not in children]
    root = path[0] if path else (roots[0] if roots else None)
    if path and roots and path[0] not in roots:
        problems.append(f"taken path starts at {path[0]!r}, not at the root")
    if not path:
        problems.append("no taken path logged")
    else:
        leaf = next((n for n in nodes if n.id == path[-1]), None)
        if leaf is None:
            problems.append(f"taken path ends at unknown node {path[-1]!r}")
        elif leaf.command is None:
            problems.append(f"taken path ends at {leaf.id!r}, which is not a leaf command")
        elif command is not None and leaf.command != command:
            problems.append(
                f"taken path ends at {leaf.command}, but the logged command is {command}"
            )
    return TreeView(nodes, edges, path, root, tuple(dict.fromkeys(problems)))


# --- graphs ------------------------------------------------------------------------------


class _Graph:
    """A directed graph with attributes, as small as the builders below need.

    ``explain`` builds its graphs here and hands out plain data (``graph_data``), so it
    does not import networkx (~50-120 ms of a ~0.3 s command: its ``__init__`` imports every
    algorithm). Nodes and edges iterate in networkx's order (nodes as added; edges by source
    node in that order, then by target as added), so the data is the same as from a
    ``networkx.DiGraph`` built by the same calls."""

    def __init__(self, **graph: Any) -> None:
        self.graph: dict[str, Any] = graph
        self.nodes: dict[str, dict[str, Any]] = {}
        self._succ: dict[str, dict[str, dict[str, Any]]] = {}

    def __contains__(self, node: str) -> bool:
        return node in self.nodes

    def add_node(self, node: str, **attrs: Any) -> None:
        self.nodes.setdefault(node, {}).update(attrs)

    def add_edge(self, u: str, v: str, **attrs: Any) -> None:
        for end in (u, v):
            self.nodes.setdefault(end, {})
        self._succ.setdefault(u, {}).setdefault(v, {}).update(attrs)

    def edge(self, u: str, v: str) -> dict[str, Any] | None:
        """The attributes of edge ``u -> v`` (None when there is no such edge)."""
        return self._succ.get(u, {}).get(v)

    def edges(self) -> Iterable[tuple[str, str, dict[str, Any]]]:
        for u in self.nodes:
            for v, data in self._succ.get(u, {}).items():
                yield u, v, data

    def data(self) -> dict[str, Any]:
        return {
            "graph": dict(self.graph),
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
    cycle: Cycle, chains: DecisionChains, decision: Decision | None = None
) -> nx.DiGraph:
    """The decision's causal graph: evidence -> entity -> belief nodes -> factor -> action.

    Node attributes: ``kind`` (sensor, evidence, entity, belief, action), ``label``,
    ``missing`` (a placeholder for something the log does not hold). Edge attributes:
    ``level`` (the chain level it documents), ``documented``, ``detail``, ``factors`` (which
    factor chains use it) and, for belief edges, ``rule`` and ``p``.
    """
    return _causal(cycle, chains, decision).to_networkx()


def causal_graph_data(
    cycle: Cycle, chains: DecisionChains, decision: Decision | None = None
) -> dict[str, Any]:
    """``graph_data(causal_graph(...))``, built without networkx."""
    return _causal(cycle, chains, decision).data()


def _causal(cycle: Cycle, chains: DecisionChains, decision: Decision | None) -> _Graph:
    decision = decision or read_decision(cycle)
    belief = _mapping(layer_with_defaults(cycle, TOPIC_BELIEF)) or {}
    perception = _mapping(layer_with_defaults(cycle, TOPIC_PERCEPTION)) or {}
    nodes = {str(n.get("id")): n for n in _dicts(belief.get("nodes"))}
    edges = {(str(e.get("parent")), str(e.get("child"))): e for e in _dicts(belief.get("edges"))}
    entities = {str(e.get("id")): e for e in _dicts(perception.get("entities"))}
    sensors = {(m.topic, m.log_time_ns) for m in cycle.sensors}

    g = _Graph(cycle=cycle.cycle, t_ns=cycle.t_ns, command=decision.command)
    g.add_node(
        ACTION_NODE,
        kind="action",
        label=decision.command or "? (action not logged)",
        missing=decision.command is None,
    )
    builder = _GraphBuilder(g, nodes, edges, entities, sensors)
    for chain in chains.factors:
        builder.add_chain(chain)
    return g


class _GraphBuilder:
    def __init__(
        self,
        g: _Graph,
        nodes: Mapping[str, Mapping[str, Any]],
        edges: Mapping[tuple[str, str], Mapping[str, Any]],
        entities: Mapping[str, Mapping[str, Any]],
        sensors: set[tuple[str, int]],
    ) -> None:
        self.g = g
        self.nodes = nodes
        self.edges = edges
        self.entities = entities
        self.sensors = sensors

    def _node(self, node_id: str, **attrs: Any) -> str:
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

    def _edge(self, u: str, v: str, chain: FactorChain, link: Link, **attrs: Any) -> None:
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
            label = f"{label} = {format_value(value, _str(raw.get('unit')))}"
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
        entity_id = _str(raw_node.get("entity")) if raw_node else None
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
        evidence = list(_dicts(entity.get("evidence"))) if entity else []
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
                label=f"{topic} @ {int(when) / 1e9:.3f} s" if when.isdigit() else sensor_link.ref,
                in_cycle=logged,
            )
        else:
            sensor_key = self._placeholder("sensor_reading", sensor_link, evidence_key)
        self._edge(sensor_key, evidence_key, chain, sensor_link)


def _pick_evidence(
    evidence: list[Mapping[str, Any]], ref_label: str
) -> tuple[int, Mapping[str, Any]] | None:
    """The evidence item whose ref the chain followed, else the first item logged."""
    for index, item in enumerate(evidence):
        ref = _mapping(item.get("ref"))
        if ref and f"{ref.get('topic')}@{ref.get('log_time_ns')}" == ref_label:
            return index, item
    return (0, evidence[0]) if evidence else None


def _entity_label(entity_id: str, entity: Mapping[str, Any]) -> str:
    cls = _str(entity.get("class")) or "?"
    confidence = _mapping(entity.get("confidence")) or {}
    p = confidence.get(cls)
    shown = f" {p:.2f}" if isinstance(p, int | float) else ""
    return f"{cls}{shown} ({entity_id})"


def _evidence_label(item: Mapping[str, Any]) -> str:
    sensor = _str(item.get("sensor")) or "?"
    region = _mapping(item.get("region"))
    where = ""
    if region:
        values = ", ".join(
            f"{v:g}" if isinstance(v, int | float) else str(v) for v in region.get("values") or ()
        )
        where = f" {region.get('kind')} [{values}]"
    weight = item.get("weight")
    w = f" w={weight:.2f}" if isinstance(weight, int | float) else ""
    return f"{sensor}{where}{w}"


def tree_graph(tree: TreeView) -> nx.DiGraph:
    """The counterfactual decision tree as a DiGraph; ``taken`` marks the chosen path."""
    return _tree(tree).to_networkx()


def tree_graph_data(tree: TreeView) -> dict[str, Any]:
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


def graph_data(g: nx.DiGraph) -> dict[str, Any]:
    """A graph as plain JSON data: ``{"graph": {...}, "nodes": [...], "edges": [...]}``."""
    return {
        "graph": dict(g.graph),
        "nodes": [{"id": n, **data} for n, data in g.nodes(data=True)],
        "edges": [{"source": u, "target": v, **data} for u, v, data in g.edges(data=True)],
    }


# --- lenient JSON access -----------------------------------------------------------------


def _mapping(value: Any) -> Mapping[str, Any] | None:
    return value if isinstance(value, Mapping) else None


def _dicts(value: Any) -> Iterable[Mapping[str, Any]]:
    if isinstance(value, list):
        return [v for v in value if isinstance(v, Mapping)]
    return ()


def _str(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def _num(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)
