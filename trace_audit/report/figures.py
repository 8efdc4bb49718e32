"""The report's figures, drawn with matplotlib's SVG backend and laid out with networkx.

Each function takes the gathered ``ReportData`` and returns one ``<svg>`` element as text,
ready to inline in the page: no XML prolog, no metadata, no namespace URLs, glyphs as paths
(no font is fetched or needed) and every ``id`` prefixed with the figure's name so several
figures share one page without their clip paths colliding. Text from the log reaches the SVG
only through matplotlib, which escapes it, and as glyph outlines.
"""

from __future__ import annotations

import io
import re
import textwrap
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from trace_audit.report.data import EntityView, ReportData

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "COMMAND_COLOURS",
    "MAX_ENTITIES",
    "MAX_FACTORS",
    "MAX_GRAPH_NODES",
    "causal_figure",
    "command_colour",
    "execution_figure",
    "factors_figure",
    "scene_figure",
    "tree_figure",
]

COMMAND_COLOURS = {
    "STOP": "#d62728",
    "SLOW": "#ff9f1c",
    "CONTINUE": "#2ca02c",
    "REROUTE": "#1f77b4",
}
# A log may hold anything (docs/integrity.md, hostile files): the figures draw at most this
# much, and the page says what was left out; explain --json has all of it.
MAX_FACTORS = 8
MAX_ENTITIES = 60
MAX_GRAPH_NODES = 150

_OTHER_COLOURS = ("#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
_MARKED = "#222222"
_BROKEN = "#c0392b"
_WRAP = 24


def command_colour(command: str | None) -> str:
    """A stable colour per command: the usual ones fixed, others by a stable hash."""
    if command is None:
        return "#bbbbbb"
    known = COMMAND_COLOURS.get(command.upper())
    if known is not None:
        return known
    return _OTHER_COLOURS[sum(command.encode()) % len(_OTHER_COLOURS)]


# --- SVG plumbing ------------------------------------------------------------------------


@contextmanager
def _style() -> Iterator[None]:
    import matplotlib

    with matplotlib.rc_context(
        {
            "svg.fonttype": "path",  # glyph outlines: the page needs no font
            "svg.hashsalt": "trace-report",  # ids stable from run to run
            "font.family": "DejaVu Sans",
            "font.size": 9,
            "axes.spines.top": False,
            "axes.spines.right": False,
            "axes.titlesize": 10,
            "axes.titleweight": "bold",
        }
    ):
        yield


def _figure(width_in: float, height_in: float) -> Figure:
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), layout="constrained")


_PROLOG = re.compile(r"^.*?(?=<svg)", re.S)
_METADATA = re.compile(r"<metadata>.*?</metadata>\s*", re.S)
_NAMESPACES = re.compile(r'\s+xmlns(:\w+)?="[^"]*"')
_SIZE = re.compile(r'(<svg[^>]*?)\s+width="[^"]*"\s+height="[^"]*"')


def _svg(fig: Figure, name: str, title: str) -> str:
    """``fig`` as an inline ``<svg>``, ids prefixed with ``name``, titled for screen readers."""
    buffer = io.StringIO()
    fig.savefig(buffer, format="svg", metadata={"Date": None, "Creator": None})
    text = _METADATA.sub("", _PROLOG.sub("", buffer.getvalue(), count=1))
    text = _NAMESPACES.sub("", text)
    text = _SIZE.sub(r"\1", text, count=1)
    text = re.sub(r'\bid="([^"]+)"', rf'id="{name}-\1"', text)
    text = re.sub(r'href="#([^"]+)"', rf'href="#{name}-\1"', text)
    text = re.sub(r"url\(#([^)]+)\)", rf"url(#{name}-\1)", text)
    from html import escape

    label = escape(title, quote=True)
    return text.replace("<svg ", f'<svg role="img" aria-label="{label}" class="figure" ', 1)


def _seconds(t_ns: int) -> float:
    return t_ns / 1e9


def _wrap(text: str, width: int = _WRAP, lines: int = 4) -> str:
    wrapped = textwrap.wrap(text, width) or [""]
    if len(wrapped) > lines:
        wrapped = [*wrapped[: lines - 1], wrapped[lines - 1][: width - 1] + "…"]
    return "\n".join(wrapped)


def _command_bands(ax: Axes, data: ReportData) -> None:
    """The command in force as coloured bands behind a time plot; gaps hatched."""
    for span in data.timeline.rows:
        ax.axvspan(
            _seconds(span.t_ns),
            _seconds(span.t_ns + span.held_ns),
            color=command_colour(span.command),
            alpha=0.13,
            lw=0,
        )
    for gap in data.timeline.gaps:
        ax.axvspan(
            _seconds(gap.after_t_ns + gap.period_ns),
            _seconds(gap.before_t_ns),
            facecolor="none",
            edgecolor="#555555",
            hatch="////",
            lw=0,
        )
    ax.axvline(_seconds(data.explanation.t_ns), color=_MARKED, lw=1.2, ls="-")


def _command_legend(fig: Figure, data: ReportData, extra: Sequence[Any] = ()) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    commands = dict.fromkeys(span.command for span in data.timeline.rows)
    handles: list[Any] = [
        Patch(color=command_colour(c), alpha=0.35, label=c or "no action") for c in commands
    ]
    handles.append(Line2D([], [], color=_MARKED, lw=1.2, label="decision explained"))
    if data.timeline.gaps:
        handles.append(
            Patch(facecolor="none", edgecolor="#555555", hatch="////", label="gap (no seal)")
        )
    handles += extra
    fig.legend(
        handles=handles, loc="outside upper center", ncols=min(len(handles), 5), frameon=False
    )


# --- factors over time --------------------------------------------------------------------


def factors_figure(data: ReportData) -> str:
    """Each factor of the decision over the window, its thresholds, the commands as bands."""
    names = list(data.factor_units)
    numeric = [n for n in names if any(n in s.factors for s in data.samples)][:MAX_FACTORS]
    with _style():
        rows = max(1, len(numeric))
        fig = _figure(7.5, 1.2 + 1.7 * rows)
        axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
        for ax, name in zip(axes, numeric, strict=False):
            _factor_axis(ax, data, name)
        if not numeric:
            axes[0].text(
                0.5, 0.5, "no numeric factor logged", ha="center", transform=axes[0].transAxes
            )
            _command_bands(axes[0], data)
        axes[-1].set_xlabel("log time (s)")
        _command_legend(fig, data)
        return _svg(fig, "factors", "The decision's factors over the window")


def _factor_axis(ax: Axes, data: ReportData, name: str) -> None:
    unit = data.factor_units.get(name)
    # A cycle whose action does not name the factor breaks the line (NaN), so values of
    # two different situations are never joined.
    xs = [_seconds(s.t_ns) for s in data.samples]
    ys = [s.factors.get(name, float("nan")) for s in data.samples]
    _command_bands(ax, data)
    ax.plot(xs, ys, ".", ms=2.5, color="#333333")
    ax.plot(xs, ys, "-", lw=0.8, color="#333333", alpha=0.5)
    for cf in data.decision.counterfactuals:
        threshold = _number(cf.threshold)
        if cf.name != name or threshold is None:
            continue
        ax.axhline(threshold, color=command_colour(cf.would_select), ls="--", lw=1)
        ax.annotate(
            cf.text,
            (1.0, threshold),
            xycoords=("axes fraction", "data"),
            xytext=(-4, 3),
            textcoords="offset points",
            ha="right",
            va="bottom",
            fontsize=8,
            color=command_colour(cf.would_select),
            bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1},
        )
    now = next((f for f in data.decision.factors if f.label == name), None)
    value = _number(now.value) if now is not None else None
    if now is not None and value is not None:
        ax.plot([_seconds(data.explanation.t_ns)], [value], "o", color=_MARKED, ms=5)
        ax.annotate(
            now.shown,
            (_seconds(data.explanation.t_ns), value),
            xytext=(6, 6),
            textcoords="offset points",
            fontsize=8,
            fontweight="bold",
            va="bottom",
            bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1},
        )
    ax.set_ylabel(f"{name} ({unit})" if unit else name)
    ax.set_xlim(_seconds(data.start_ns), _seconds(data.end_ns))


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else None


# --- the scene at t ----------------------------------------------------------------------

_CLASS_MARKERS = {"person": "o", "forklift": "s", "vehicle": "s", "pallet": "D", "corridor": ">"}


def scene_figure(data: ReportData) -> str:
    """Top-down plot of the robot and the entities it perceived at t; entities whose
    evidence failed are drawn hollow and red, each entity's logged distance as a line."""
    placed = [e for e in data.entities[:MAX_ENTITIES] if e.x is not None and e.y is not None]
    with _style():
        fig = _figure(7.5, 4.4)
        ax = fig.add_subplot()
        ax.set_aspect("equal", adjustable="box")
        robot = data.robot
        if robot is not None:
            _draw_robot(ax, robot.x, robot.y, robot.heading_rad)
        taken: list[tuple[float, float]] = []
        for entity in placed:
            x, y = float(entity.x or 0.0), float(entity.y or 0.0)
            colour = _BROKEN if entity.evidence_failed else _ENTITY
            if robot is not None and entity.distance and entity.cls != "corridor":
                ax.plot([robot.x, x], [robot.y, y], ":", color=colour, lw=1)
            ax.plot(
                [x],
                [y],
                _CLASS_MARKERS.get(entity.cls, "^"),
                ms=11,
                ls="none",
                mfc="none" if entity.evidence_failed else colour,
                mec=colour,
                mew=1.6,
            )
            # Entities close together get their labels on alternate sides, each with a
            # leader line, so a label is never read as another entity's.
            near = sum(1 for px, py in taken if abs(x - px) < 1.5 and abs(y - py) < 1.0)
            taken.append((x, y))
            offset = _LABEL_OFFSETS[near % len(_LABEL_OFFSETS)]
            ax.annotate(
                _entity_label(entity),
                (x, y),
                xytext=offset,
                textcoords="offset points",
                fontsize=8,
                color=colour,
                va="center",
                ha="left" if offset[0] > 0 else "right",
                arrowprops={"arrowstyle": "-", "color": colour, "lw": 0.6, "shrinkB": 6},
            )
        frames = sorted({e.frame for e in placed}) or ["map"]
        ax.set_xlabel(f"x (m, {', '.join(frames)} frame)")
        ax.set_ylabel("y (m)")
        ax.grid(True, lw=0.4, alpha=0.5)
        if not placed and robot is None:
            ax.text(0.5, 0.5, "no pose logged", ha="center", transform=ax.transAxes)
        else:
            points = [(float(e.x or 0.0), float(e.y or 0.0)) for e in placed]
            if robot is not None:
                points.append((robot.x, robot.y))
            _frame(ax, points)
        return _svg(fig, "scene", "The robot and the entities it perceived at the decision")


_ENTITY = "#1f4e79"
_MIN_SPAN_M = 4.0
"""The scene shows at least this many metres each way, so a lone entity is not a dot in a
blown-up grid of centimetres."""


def _frame(ax: Axes, points: list[tuple[float, float]]) -> None:
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    cx, cy = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    half = max(max(xs) - min(xs), max(ys) - min(ys), _MIN_SPAN_M) * 0.65
    ax.set_xlim(cx - half * 1.6, cx + half * 1.6)  # the plot is wider than tall
    ax.set_ylim(cy - half, cy + half)


_LABEL_OFFSETS = ((28, 26), (28, -30), (-28, 26), (-28, -30))


def _entity_label(entity: EntityView) -> str:
    conf = f" {entity.confidence:.2f}" if entity.confidence is not None else ""
    lines = [f"{entity.id}: {entity.cls}{conf}"]
    if entity.distance and entity.cls != "corridor":
        lines.append(f"{entity.distance} from the robot")
    sensors = sorted({e.sensor for e in entity.evidence if e.resolved})
    lines.append("evidence FAILED" if entity.evidence_failed else "seen by " + ", ".join(sensors))
    return "\n".join(_wrap(line, 34, 1) for line in lines)


def _draw_robot(ax: Axes, x: float, y: float, heading: float) -> None:
    """The robot as a dark disc with an arrow along its heading."""
    import math

    ax.plot([x], [y], "o", ms=14, color="#444444", zorder=3)
    ax.annotate(
        "",
        (x + 0.9 * math.cos(heading), y + 0.9 * math.sin(heading)),
        (x, y),
        arrowprops={"arrowstyle": "-|>", "color": "#444444", "lw": 1.6},
        zorder=3,
    )
    ax.annotate(
        "robot",
        (x, y),
        xytext=(0, -16),
        textcoords="offset points",
        ha="center",
        va="top",
        fontsize=8,
        fontweight="bold",
        color="#444444",
    )


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
    with _style():
        if not 0 < g.number_of_nodes() <= MAX_GRAPH_NODES or not nx.is_directed_acyclic_graph(g):
            fig = _figure(7.5, 1.5)
            ax = fig.add_subplot()
            ax.axis("off")
            ax.text(0.5, 0.5, "no causal chain logged", ha="center", transform=ax.transAxes)
            return _svg(fig, "causal", "The causal chain")
        for layer, nodes in enumerate(nx.topological_generations(g)):
            for node in nodes:
                g.nodes[node]["layer"] = layer
        pos = nx.multipartite_layout(g, subset_key="layer", align="vertical", scale=1.0)
        layers = 1 + max(g.nodes[n]["layer"] for n in g)
        tallest = max(sum(1 for n in g if g.nodes[n]["layer"] == i) for i in range(layers))
        broken = any(not d["documented"] for _, _, d in g.edges(data=True))
        fig = _figure(7.5, max(1.6, 0.8 * tallest + 0.7) + (0.9 if broken else 0.0))
        ax = fig.add_subplot()
        ax.axis("off")
        _draw_causal(ax, g, pos)
        return _svg(fig, "causal", "The causal chain from sensor readings to the action")


def _edge_attrs(edge: Mapping[str, Any]) -> dict[str, Any]:
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


def _draw_causal(ax: Axes, g: Any, pos: Mapping[str, Any]) -> None:
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
            edge_color="#555555" if d["documented"] else _BROKEN,
            style="solid" if d["documented"] else "dashed",
            width=1.0 if d["documented"] else 1.4,
            connectionstyle=f"arc3,rad={-_ARC if long else 0.0}",
            min_source_margin=_half_width_pt(str(g.nodes[u].get("label", u))),
            min_target_margin=_half_width_pt(str(g.nodes[v].get("label", v))),
        )
        if d["documented"]:
            continue
        # The reason goes under the broken link (the nodes leave no room beside it), joined
        # to it by a thin red leader.
        (x1, y1), (x2, y2) = pos[u], pos[v]
        lift = _ARC * abs(x2 - x1) / 2 if long else 0.0
        mid = ((x1 + x2) / 2, (y1 + y2) / 2 + lift)
        ax.annotate(
            _wrap("BROKEN: " + d["detail"], 20, 4),
            mid,
            xytext=(mid[0], min(y1, y2) - _BELOW),
            fontsize=6.5,
            color=_BROKEN,
            ha="center",
            va="top",
            bbox={"boxstyle": "round,pad=0.25", "fc": "white", "ec": _BROKEN, "lw": 0.6},
            arrowprops={"arrowstyle": "-", "color": _BROKEN, "lw": 0.6},
        )
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
                "ec": _BROKEN if kind == "missing" else "#666666",
                "ls": "--" if kind == "missing" else "-",
                "lw": 0.8,
            },
        )
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    arcs = [_ARC * abs(pos[v][0] - pos[u][0]) / 2 for u, v in g.edges() if layer[v] - layer[u] > 1]
    broken = any(not d["documented"] for _, _, d in g.edges(data=True))
    ax.set_xlim(min(xs) - 0.12, max(xs) + 0.12)
    ax.set_ylim(
        min(ys) - (0.12 + 3 * _BELOW if broken else 0.12),
        max(ys) + 0.12 + max(arcs, default=0.0),
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
    if root not in source or len(source) > MAX_GRAPH_NODES or not nx.is_tree(source):
        return None
    pos = _tidy_layout(source, root)
    depth = 1 + round(-min(y for _, y in pos.values()))
    with _style():
        fig = _figure(7.5, 0.8 * depth + 0.4)
        ax = fig.add_subplot()
        ax.axis("off")
        _draw_tree(ax, source, pos)
        return _svg(fig, "tree", "The counterfactual decision tree with the taken path")


def _tidy_layout(g: Any, root: str) -> dict[str, tuple[float, float]]:
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


def _draw_tree(ax: Axes, g: Any, pos: Mapping[str, Any]) -> None:
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
            _wrap(label, 18, 3),
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


# --- execution ---------------------------------------------------------------------------


def execution_figure(data: ReportData) -> str:
    """Intended vs actual per execution channel, and the deviation with failed checks."""
    channels = list(dict.fromkeys(c for s in data.samples for c in s.channels))
    with _style():
        rows = len(channels) + 1
        fig = _figure(7.5, 1.2 + 1.45 * rows)
        axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
        for ax, channel in zip(axes, channels, strict=False):
            _channel_axis(ax, data, channel)
        _deviation_axis(axes[-1], data)
        axes[-1].set_xlabel("log time (s)")
        from matplotlib.lines import Line2D

        lines = [
            Line2D([], [], color="#1f4e79", ls="--", lw=1.2, label="intended"),
            Line2D([], [], color="#333333", lw=1.0, label="actual"),
        ]
        if any(s.failed_checks for s in data.samples):
            lines.append(Line2D([], [], color=_BROKEN, marker="x", ls="none", label="check failed"))
        _command_legend(fig, data, lines)
        return _svg(fig, "execution", "Intended and actual motion over the window")


def _channel_axis(ax: Axes, data: ReportData, channel: str) -> None:
    _command_bands(ax, data)
    xs = [_seconds(s.t_ns) for s in data.samples if channel in s.channels]
    pairs = [s.channels[channel] for s in data.samples if channel in s.channels]
    ax.plot(xs, [_nan(p[0]) for p in pairs], "--", lw=1.2, color="#1f4e79")
    ax.plot(xs, [_nan(p[1]) for p in pairs], "-", lw=1.0, color="#333333")
    ax.set_ylabel(_wrap(channel, 16, 2))
    ax.set_xlim(_seconds(data.start_ns), _seconds(data.end_ns))


def _deviation_axis(ax: Axes, data: ReportData) -> None:
    _command_bands(ax, data)
    xs = [_seconds(s.t_ns) for s in data.samples]
    ax.plot(xs, [_nan(s.deviation) for s in data.samples], "-", lw=1.0, color="#333333")
    failed = [s for s in data.samples if s.failed_checks]
    if failed:
        ax.plot(
            [_seconds(s.t_ns) for s in failed],
            [_nan(s.deviation) for s in failed],
            "x",
            ms=4,
            color=_BROKEN,
        )
    ax.set_ylabel("deviation")
    ax.set_xlim(_seconds(data.start_ns), _seconds(data.end_ns))


def _nan(value: float | None) -> float:
    return float("nan") if value is None else value
