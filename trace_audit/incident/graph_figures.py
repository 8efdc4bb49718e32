"""The report's graph figures: the causal chain of the decision and its counterfactual tree,
laid out with networkx."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from typing import TYPE_CHECKING, TypeAlias, TypedDict

from trace_audit.incident.data import ReportData
from trace_audit.incident.drawing import (
    BROKEN,
    MAX_GRAPH_NODES,
    command_colour,
    figure_style,
    new_figure,
    to_svg,
    wrap_label,
)

if TYPE_CHECKING:
    import networkx as nx
    import numpy as np
    from matplotlib.axes import Axes
    from numpy.typing import NDArray

    from trace_audit.causal import EdgeData

__all__ = ["causal_figure", "tree_figure"]

_Point: TypeAlias = "tuple[float, float] | NDArray[np.float64]"
"""A node's position: networkx's layouts give numpy arrays, ``_tidy_layout`` tuples."""


class _DrawnEdge(TypedDict):
    """What the causal figure draws of an edge."""

    documented: bool
    detail: str


# --- the causal chain --------------------------------------------------------------------

_KIND_COLOURS = {
    "sensor": "#d9e8f5",
    "evidence": "#e3f1df",
    "entity": "#fff2cc",
    "belief": "#f3e5f5",
    "action": "#fde0dc",
    "missing": "#ffffff",
}


def causal_figure(data: ReportData) -> str:
    """Sensor reading -> evidence -> entity -> belief path -> factor -> action, as a drawn
    graph (networkx layers); undocumented links dashed red with their reason."""
    import networkx as nx

    graph = data.explanation.graph
    g = nx.DiGraph()
    for node in graph["nodes"]:
        g.add_node(node["id"], **{k: v for k, v in node.items() if k != "id"})
    for edge in graph["edges"]:
        g.add_edge(edge["source"], edge["target"], **_edge_attrs(edge))
    with figure_style():
        if not 0 < g.number_of_nodes() <= MAX_GRAPH_NODES or not nx.is_directed_acyclic_graph(g):
            fig = new_figure(7.5, 1.5)
            ax = fig.add_subplot()
            ax.axis("off")
            ax.text(0.5, 0.5, "no causal chain logged", ha="center", transform=ax.transAxes)
            return to_svg(fig, "causal", "The causal chain")
        for layer, nodes in enumerate(nx.topological_generations(g)):
            for node in nodes:
                g.nodes[node]["layer"] = layer
        pos = nx.multipartite_layout(g, subset_key="layer", align="vertical", scale=1.0)
        layers = 1 + max(g.nodes[n]["layer"] for n in g)
        tallest = max(sum(1 for n in g if g.nodes[n]["layer"] == i) for i in range(layers))
        broken = any(not d["documented"] for _, _, d in g.edges(data=True))
        fig = new_figure(7.5, max(1.6, 0.8 * tallest + 0.7) + (0.9 if broken else 0.0))
        ax = fig.add_subplot()
        ax.axis("off")
        _draw_causal(ax, g, pos)
        return to_svg(fig, "causal", "The causal chain from sensor readings to the action")


def _edge_attrs(edge: EdgeData) -> _DrawnEdge:
    return {
        "documented": bool(edge.get("documented", True)),
        "detail": str(edge.get("detail") or ""),
    }


def _half_width_pt(label: str) -> float:
    """About half the width of a node's box in points (7 pt text, wrapped as drawn)."""
    longest = max((len(line) for line in _node_text(label).splitlines()), default=1)
    return 1.9 * longest + 5.0


def _node_text(label: str) -> str:
    lines = textwrap.wrap(label, 13, break_long_words=False) or [""]
    return "\n".join(lines[:4] + (["…"] if len(lines) > 4 else []))


_ARC = 0.3
"""Bend of an edge that skips a layer, so it arcs over the nodes in between."""
_BELOW = 0.1
"""How far under the row of nodes the reason of a broken link is written (layout units)."""


def _draw_causal(ax: Axes, g: nx.DiGraph, pos: Mapping[str, _Point]) -> None:
    import networkx as nx

    layer = {n: g.nodes[n]["layer"] for n in g}
    for u, v, d in g.edges(data=True):
        long = layer[v] - layer[u] > 1
        nx.draw_networkx_edges(
            g,
            pos,
            edgelist=[(u, v)],
            ax=ax,
            arrows=True,
            arrowsize=10,
            edge_color="#555555" if d["documented"] else BROKEN,
            style="solid" if d["documented"] else "dashed",
            width=1.0 if d["documented"] else 1.4,
            connectionstyle=f"arc3,rad={-_ARC if long else 0.0}",
            min_source_margin=_half_width_pt(str(g.nodes[u].get("label", u))),
            min_target_margin=_half_width_pt(str(g.nodes[v].get("label", v))),
        )
        if not d["documented"]:
            _broken_reason(ax, pos[u], pos[v], d["detail"], arcs=long)
    _draw_causal_nodes(ax, g, pos)
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    arcs = [_ARC * abs(pos[v][0] - pos[u][0]) / 2 for u, v in g.edges() if layer[v] - layer[u] > 1]
    broken = any(not d["documented"] for _, _, d in g.edges(data=True))
    ax.set_xlim(min(xs) - 0.12, max(xs) + 0.12)
    ax.set_ylim(
        min(ys) - (0.12 + 3 * _BELOW if broken else 0.12),
        max(ys) + 0.12 + max(arcs, default=0.0),
    )


def _broken_reason(ax: Axes, start: _Point, end: _Point, detail: str, *, arcs: bool) -> None:
    """The reason a link is broken, under it (the nodes leave no room beside it), joined to
    it by a thin red leader."""
    (x1, y1), (x2, y2) = start, end
    lift = _ARC * abs(x2 - x1) / 2 if arcs else 0.0
    mid = ((x1 + x2) / 2, (y1 + y2) / 2 + lift)
    ax.annotate(
        wrap_label("BROKEN: " + detail, 20, 4),
        mid,
        xytext=(mid[0], min(y1, y2) - _BELOW),
        fontsize=6.5,
        color=BROKEN,
        ha="center",
        va="top",
        bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": BROKEN, "lw": 0.6},
        arrowprops={"arrowstyle": "-", "color": BROKEN, "lw": 0.6},
    )


def _draw_causal_nodes(ax: Axes, g: nx.DiGraph, pos: Mapping[str, _Point]) -> None:
    """Each node as a labelled box in its kind's colour; a placeholder dashed and red."""
    for node, (x, y) in pos.items():
        attrs = g.nodes[node]
        kind = "missing" if attrs.get("missing") else str(attrs.get("kind", "belief"))
        ax.text(
            x,
            y,
            _node_text(str(attrs.get("label", node))),
            fontsize=7,
            ha="center",
            va="center",
            bbox={
                "boxstyle": "round,pad=0.35",
                "fc": _KIND_COLOURS.get(kind, "#eeeeee"),
                "ec": BROKEN if kind == "missing" else "#666666",
                "ls": "--" if kind == "missing" else "-",
                "lw": 0.8,
            },
        )


# --- the counterfactual tree -------------------------------------------------------------


def tree_figure(data: ReportData) -> str | None:
    """The counterfactual decision tree, top-down, the taken path bold green."""
    import networkx as nx

    tree = data.explanation.tree
    if tree is None:
        return None
    source = nx.DiGraph()
    for node in tree["nodes"]:
        source.add_node(node["id"], **{k: v for k, v in node.items() if k != "id"})
    for edge in tree["edges"]:
        source.add_edge(
            edge["source"],
            edge["target"],
            **{k: v for k, v in edge.items() if k not in ("source", "target")},
        )
    root = tree["graph"].get("root")
    if root is None or root not in source:
        return None
    if len(source) > MAX_GRAPH_NODES or not nx.is_tree(source):
        return None
    pos = _tidy_layout(source, root)
    depth = 1 + round(-min(y for _, y in pos.values()))
    with figure_style():
        fig = new_figure(7.5, 0.8 * depth + 0.4)
        ax = fig.add_subplot()
        ax.axis("off")
        _draw_tree(ax, source, pos)
        return to_svg(fig, "tree", "The counterfactual decision tree with the taken path")


def _tidy_layout(g: nx.DiGraph, root: str) -> dict[str, tuple[float, float]]:
    """Leaves side by side in depth-first order, each parent centred over its children,
    one row per depth: a tree drawn this way has no crossing edges."""
    import networkx as nx

    depth = nx.shortest_path_length(g, root)
    x: dict[str, float] = {}
    leaves = 0
    for node in nx.dfs_postorder_nodes(g, root):
        children = list(g.successors(node))
        if children:
            x[node] = sum(x[c] for c in children) / len(children)
        else:
            x[node] = float(leaves)
            leaves += 1
    return {n: (x[n], -float(depth[n])) for n in x}


def _draw_tree(ax: Axes, g: nx.DiGraph, pos: Mapping[str, _Point]) -> None:
    import networkx as nx

    for taken in (False, True):
        edges = [(u, v) for u, v, d in g.edges(data=True) if bool(d.get("taken")) == taken]
        nx.draw_networkx_edges(
            g,
            pos,
            edgelist=edges,
            ax=ax,
            arrows=False,
            edge_color="#2ca02c" if taken else "#aaaaaa",
            width=2.6 if taken else 1.0,
        )
    for u, v, d in g.edges(data=True):
        (x1, y1), (x2, y2) = pos[u], pos[v]
        if d.get("label"):
            ax.text(
                (x1 + x2) / 2,
                (y1 + y2) / 2,
                str(d["label"]),
                fontsize=7,
                ha="center",
                va="center",
                color="#555555",
                bbox={"fc": "white", "ec": "none", "pad": 0.5},
            )
    for node, (x, y) in pos.items():
        attrs = g.nodes[node]
        taken = bool(attrs.get("taken"))
        command = attrs.get("command")
        label = str(attrs.get("label") or node)
        colour = command_colour(command) if command else "#f2f2f2"
        ax.text(
            x,
            y,
            wrap_label(label, 18, 3),
            ha="center",
            va="center",
            fontsize=7.5,
            fontweight="bold" if taken else "normal",
            color="white" if command else "#222222",
            bbox={
                "boxstyle": "round,pad=0.35",
                "fc": colour,
                "ec": "#2ca02c" if taken else "#999999",
                "lw": 2.2 if taken else 0.8,
                "alpha": 1.0 if taken or not command else 0.55,
            },
        )
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    ax.set_xlim(min(xs) - 0.6, max(xs) + 0.6)
    ax.set_ylim(min(ys) - 0.35, max(ys) + 0.35)
