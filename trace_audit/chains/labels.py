"""A factor's chain in the words of its decision's causal graph (``trace_audit.causal``):
each node and link named by the graph's labels, bottom (sensor reading) up, as
``trace-audit explain`` draws it (``label_chain``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import TYPE_CHECKING

from trace_audit.chains.model import FactorChain, Link

if TYPE_CHECKING:  # the causal graph is built from chains: its module imports this package
    from trace_audit.causal.graph import EdgeData, GraphData

__all__ = ["LabelledChain", "LabelledLink", "label_chain"]


@dataclass(frozen=True, slots=True)
class LabelledLink:
    """One link of a factor's chain, named by the labels of the decision's causal graph."""

    link: Link
    what: str
    """What it points at: a node's label, the belief path with its rules, or the ref."""

    @property
    def reached(self) -> bool:
        """False below the first missing link: nothing logged says where it would go on."""
        return self.link.documented or not self.link.detail.startswith("not reached")

    @property
    def placeholder(self) -> bool:
        """``what`` is the graph's stand-in for an undocumented node ("? ..."), which says
        nothing the link's detail does not."""
        return self.what.startswith("? ")


@dataclass(frozen=True, slots=True)
class LabelledChain:
    """A factor's chain as the causal graph draws it, bottom (sensor reading) up."""

    chain: FactorChain
    path: tuple[str, ...]
    """The labels of the chain's nodes from the bottom (a sensor reading or a placeholder)
    up to the action; the belief graph's entity node is left out (it mirrors the perception
    entity). Empty when the chain's edges do not form one path."""
    links: tuple[LabelledLink, ...]
    """The links bottom-up: sensor reading first, factor node last."""


def label_chain(chain: FactorChain, graph: GraphData, command: str | None) -> LabelledChain:
    """``chain`` named by ``graph``, the node-link JSON of its decision's causal graph
    (``trace_audit.causal.causal_graph_data``), whose action is ``command``."""
    nodes = graph["nodes"]
    labels = {n["id"]: str(n.get("label", n["id"])) for n in nodes}
    kinds = {n["id"]: n.get("belief_kind") for n in nodes}
    mine = [e for e in graph["edges"] if chain.node in e.get("factors", ())]
    by_level: dict[str, list[EdgeData]] = {}
    for edge in mine:
        by_level.setdefault(str(edge.get("level")), []).append(edge)
    path = tuple(labels.get(p, p) for p in _edge_path(mine) if kinds.get(p) != "entity")
    links = []
    for link in reversed(chain.links):
        edges = by_level.get(link.level, [])
        if link.level == "belief_path" and link.documented:
            what = _belief_path_text(graph, link.ref)
        elif link.level == "factor_node":
            what = f"{labels.get('belief:' + chain.node, chain.node)} -> {command}"
        elif edges:
            what = labels.get(edges[0]["source"], link.ref)
        else:
            what = link.ref
        links.append(LabelledLink(link, what))
    return LabelledChain(chain, path, tuple(links))


def _belief_path_text(graph: GraphData, ref: str) -> str:
    """``ped_1 -> ped_1.distance -> collision_risk (rules: a, b)``, bottom-up."""
    rules = {(e["source"], e["target"]): e.get("rule") for e in graph["edges"] if e.get("rule")}
    path = list(reversed(ref.split(" <- ")))
    used = [
        str(rules[key])
        for key in ((f"belief:{a}", f"belief:{b}") for a, b in pairwise(path))
        if key in rules
    ]
    text = " -> ".join(path)
    return f"{text} (rules: {', '.join(used)})" if used else text


def _edge_path(edges: Sequence[EdgeData]) -> list[str]:
    """The nodes of a chain's edges from the bottom up to the action; [] unless they form
    one path."""
    succ = {e["source"]: e["target"] for e in edges}
    targets = set(succ.values())
    starts = [s for s in succ if s not in targets]
    if len(starts) != 1:
        return []
    path = [starts[0]]
    while path[-1] in succ and len(path) <= len(edges):
        path.append(succ[path[-1]])
    return path
