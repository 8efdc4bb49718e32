"""One decision as an investigator reads it: the ``Decision`` view model and ``read_decision``.

``read_decision`` turns a logged cycle into a ``Decision``: the action, its rationale and
factors, alternatives, counterfactuals, the counterfactual decision tree and the execution
record. It reads the plain JSON of each layer (``Cycle.layer``, omitted optional fields at
their schema defaults) and is lenient about missing fields, so a warm-tier summary or a
damaged record still yields what was logged.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from itertools import pairwise

from trace_audit.causal.defaults import layer_with_defaults
from trace_audit.causal.lenient import as_float, as_list, as_mapping, as_str, mappings
from trace_audit.jsonout import OMIT_EMPTY
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.flags import split_flags
from trace_runtime.records import TOPIC_ACTION, TOPIC_BELIEF, TOPIC_EXECUTION, TOPIC_PERCEPTION

__all__ = [
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
    "format_value",
    "read_decision",
]

Scalar = float | int | bool | str


def format_value(value: object, unit: str | None = None) -> str:
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
    ``scenario:`` label (``trace_runtime.flags``). ``channels`` and ``deviation_unit`` are
    left out of JSON when a record has none: a profile 1.0 record names neither.
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


def read_decision(cycle: Cycle, *, with_tree: bool = True) -> Decision:
    """The decision logged in ``cycle`` (full or warm summary), read leniently, with
    omitted optional fields at their schema defaults. ``with_tree=False``: leave the
    counterfactual tree out (``tree`` None), for a reader of the other fields alone; the
    tree is most of the cost of a decision."""
    action = as_mapping(layer_with_defaults(cycle, TOPIC_ACTION))
    execution = as_mapping(layer_with_defaults(cycle, TOPIC_EXECUTION))
    layers = tuple(
        topic
        for topic in (TOPIC_PERCEPTION, TOPIC_BELIEF, TOPIC_ACTION, TOPIC_EXECUTION)
        if topic in cycle.payloads or (cycle.summary and topic in cycle.summary)
    )
    rationale = as_mapping(action.get("rationale")) if action else None
    factors = tuple(_factor(f) for f in mappings(rationale.get("factors") if rationale else None))
    by_node = {f.node: f for f in factors}
    command = as_str(action.get("command")) if action else None
    tree = as_mapping(action.get("tree")) if action else None
    return Decision(
        cycle=cycle.cycle,
        t_ns=cycle.t_ns,
        segment=cycle.segment,
        summary=cycle.is_summary,
        command=command,
        parameters={
            str(k): float(v)
            for k, v in (as_mapping(action.get("parameters")) or {}).items()
            if isinstance(v, int | float) and not isinstance(v, bool)
        }
        if action
        else {},
        score=as_float(action.get("score")) if action else None,
        rationale=as_str(rationale.get("text")) if rationale else None,
        truncated=bool(rationale.get("truncated")) if rationale else False,
        factors=factors,
        alternatives=tuple(
            AlternativeView(
                as_str(a.get("command")) or "?",
                as_float(a.get("score")),
                as_str(a.get("rejected_because")) or "",
            )
            for a in mappings(action.get("alternatives") if action else None)
        ),
        counterfactuals=tuple(
            _counterfactual(c, by_node)
            for c in mappings(action.get("counterfactuals") if action else None)
        ),
        counterfactuals_none_applicable=bool(
            action.get("counterfactuals_none_applicable") if action else False
        ),
        tree=_tree_view(tree, command) if tree and with_tree else None,
        execution=_execution(execution) if execution else None,
        layers=layers,
    )


def _factor(raw: Mapping[str, object]) -> FactorValue:
    value = raw.get("value")
    return FactorValue(
        node=as_str(raw.get("node")) or "",
        name=as_str(raw.get("name")) or "",
        value=value if isinstance(value, int | float | str | bool) else None,
        unit=as_str(raw.get("unit")),
    )


def _counterfactual(
    raw: Mapping[str, object], factors: Mapping[str, FactorValue]
) -> CounterfactualView:
    node = as_str(raw.get("factor")) or "?"
    known = factors.get(node)
    name = known.label if known else node
    unit = known.unit if known else None
    comparison = as_str(raw.get("comparison")) or "?"
    threshold = raw.get("threshold")
    threshold = threshold if isinstance(threshold, int | float | str | bool) else None
    would = as_str(raw.get("would_select")) or "?"
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


def _execution(raw: Mapping[str, object]) -> ExecutionView:
    flags = tuple(str(f) for f in as_list(raw.get("flags")) if isinstance(f, str))
    problems, scenario = split_flags(flags)
    intended = as_mapping(raw.get("intended")) or {}
    actual = as_mapping(raw.get("actual")) or {}
    return ExecutionView(
        intended=(as_float(intended.get("linear")), as_float(intended.get("angular"))),
        actual=(as_float(actual.get("linear")), as_float(actual.get("angular"))),
        deviation=as_float(raw.get("deviation")),
        checks=tuple(
            CheckView(
                rule=as_str(c.get("rule")) or "?",
                passed=bool(c.get("passed")),
                value=as_float(c.get("value")),
                limit=as_float(c.get("limit")),
                detail=as_str(c.get("detail")) or "",
            )
            for c in mappings(raw.get("checks"))
        ),
        flags=flags,
        problems=problems,
        scenario=scenario,
        channels=tuple(
            ChannelView(
                name=as_str(c.get("name")) or "?",
                unit=as_str(c.get("unit")) or "",
                intended=as_float(c.get("intended")),
                actual=as_float(c.get("actual")),
                deviation=as_float(c.get("deviation")),
            )
            for c in mappings(raw.get("channels"))
        ),
        deviation_unit=as_str(raw.get("deviation_unit")),
    )


def _tree_view(raw: Mapping[str, object], command: str | None) -> TreeView:
    path = tuple(str(p) for p in as_list(raw.get("taken_path")) if isinstance(p, str))
    on_path = set(path)
    taken_edges = set(pairwise(path))
    nodes = tuple(
        TreeNodeView(
            id=as_str(n.get("id")) or "?",
            label=as_str(n.get("label")) or "",
            test=as_str(n.get("test")),
            command=as_str(n.get("command")),
            taken=n.get("id") in on_path,
        )
        for n in mappings(raw.get("nodes"))
    )
    edges = tuple(
        TreeEdgeView(
            parent=as_str(e.get("parent")) or "?",
            child=as_str(e.get("child")) or "?",
            label=as_str(e.get("label")) or "",
            taken=(e.get("parent"), e.get("child")) in taken_edges,
        )
        for e in mappings(raw.get("edges"))
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
