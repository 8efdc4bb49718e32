"""The two graphs ``explain`` draws as trees: each factor's causal chain, link by link,
and the counterfactual decision tree with the taken path.

The chain's labels and path come from ``trace_audit.chains.label_chain``; this module only
chooses the marks, words and styles of each line.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from trace_audit.cli.doc import Item, Seg

if TYPE_CHECKING:
    from trace_audit.chains import FactorChain, LabelledLink
    from trace_audit.explanation import Explanation

__all__ = ["chain_item", "tree_item"]

_OK = Seg("✔", "green", "[ok]")
_MISSING = Seg("✘ MISSING", "bold red", "[MISSING]")
_UNREACHED = Seg("·", "dim", "[--]")

_LEVEL_NAMES = {
    "sensor_reading": "sensor reading",
    "evidence_ref": "evidence ref",
    "entity": "perception",
    "belief_path": "belief path",
    "factor_node": "factor",
}

_MAX_TREE_DEPTH = 12
"""Levels of a counterfactual tree drawn in a terminal; deeper ones are in ``--json``."""


def chain_item(r: Explanation, chain: FactorChain) -> Item:
    """A factor's chain: its value and depth, its path of nodes, then each link bottom-up."""
    from trace_audit.chains import label_chain

    labelled = label_chain(chain, r.graph, r.decision.command)
    value = next((f for f in r.decision.factors if f.node == chain.node), None)
    shown = f" = {value.shown}" if value is not None else ""
    status = Seg("traceable", "bold green") if chain.traceable else Seg("NOT traceable", "bold red")
    root = Item(
        [
            Seg(f"{chain.name or chain.node}{shown}", "bold"),
            f"  depth {chain.depth}/{chain.expected_depth}, ",
            status,
        ]
    )
    if labelled.path:
        root.add(Seg(" -> ".join(labelled.path), "dim"))
    for link in labelled.links:
        root.add(_link_line(link))
    return root


def _link_line(labelled: LabelledLink) -> list[str | Seg]:
    link = labelled.link
    name = _LEVEL_NAMES.get(link.level, link.level)
    if link.documented:
        return [_OK, f" {name}: {labelled.what}"]
    if not labelled.reached:
        return [_UNREACHED, f" {name}: ", Seg("not reached (the chain breaks above)", "dim")]
    logged = "" if labelled.placeholder else f"{labelled.what} "
    return [_MISSING, f" {name}: {logged}", Seg(f"({link.detail})", "red")]


def tree_item(r: Explanation) -> Item:
    """The counterfactual tree from its root, the taken path marked ``=>``; a node met twice
    (a malformed tree with a cycle) is shown once, levels past ``_MAX_TREE_DEPTH`` not."""
    tree = r.tree
    assert tree is not None
    nodes = {n["id"]: n for n in tree["nodes"]}
    children: dict[str, list[Mapping[str, Any]]] = {}
    for edge in tree["edges"]:
        children.setdefault(edge["source"], []).append(edge)
    root_id = tree["graph"].get("root")
    seen: set[str] = set()

    def build(node_id: str, label: str, depth: int) -> Item:
        item = Item(_tree_line(nodes.get(node_id, {"label": node_id}), node_id, label))
        if node_id in seen:
            return item
        seen.add(node_id)
        edges = children.get(node_id, ())
        if edges and depth >= _MAX_TREE_DEPTH:
            # A policy's tree is a few levels deep; a log may hold anything. Shown bounded.
            item.children.append(Item(["   ", Seg("... deeper levels: see --json", "dim")]))
            return item
        for edge in edges:
            item.children.append(build(edge["target"], str(edge.get("label") or ""), depth + 1))
        return item

    return build(root_id if root_id is not None else next(iter(nodes), "?"), "", 0)


def _tree_line(node: Mapping[str, object], node_id: str, label: str) -> list[str | Seg]:
    taken = bool(node.get("taken"))
    text = str(node.get("label") or node_id)
    prefix = f"[{label}] " if label else ""
    chosen = taken and node.get("command") is not None
    return [
        Seg("=> ", "bold green") if taken else "   ",
        Seg(prefix, "dim"),
        Seg(text, "bold green" if taken else ""),
        Seg("  <- chosen", "bold green") if chosen else "",
    ]
