"""Export one decision's causal graph and counterfactual tree for reports: DOT, Mermaid, JSON.

The causal graph runs from sensor evidence up to the action; undocumented links are drawn
dashed and labelled MISSING, placeholders for what the log does not hold are drawn dashed
too. The tree's taken path is drawn bold. ``export_decision`` returns the text; writing it
is the caller's business.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

from trace_audit.causal import EdgeData, GraphData
from trace_audit.explanation import Explanation, explain
from trace_audit.log_source import LogSource
from trace_audit.log_time import TimeArg
from trace_runtime.errors import UsageError

__all__ = ["FORMATS", "Export", "ExportFormat", "export_decision", "render_export"]

ExportFormat = Literal["dot", "mermaid", "json"]
FORMATS: tuple[str, ...] = get_args(ExportFormat)


@dataclass(frozen=True, slots=True)
class Export:
    """The exported text of one decision's graphs, and which decision it is."""

    format: str
    cycle: int
    t_ns: int
    command: str | None
    nodes: int
    edges: int
    undocumented: int
    text: str


def export_decision(
    source: LogSource,
    *,
    t: TimeArg = None,
    cycle: int | None = None,
    fmt: str = "dot",
    robots: Sequence[str] = (),
    evidence: Sequence[str | Path] = (),
) -> Export:
    """The causal graph and counterfactual tree of the decision at ``t`` (or ``cycle``);
    ``robots`` as ``explain`` takes them (one robot's decision, or ``SeveralRobotsError``).
    Evidence resolves as explain resolves it: the recordings the log declares, ``evidence``
    (``--evidence``) for a moved copy."""
    if fmt not in FORMATS:
        raise UsageError(f"unknown export format {fmt!r} (use {', '.join(FORMATS)})")
    # No look-back is needed for the graphs: only the sensor window and the seal.
    result = explain(source, t=t, cycle=cycle, lookback_s=0, robots=robots, evidence=evidence)
    return render_export(result, fmt)


def render_export(result: Explanation, fmt: str) -> Export:
    """Render an explanation's graphs in ``fmt``."""
    graph = result.graph
    if fmt == "dot":
        text = _dot(result)
    elif fmt == "mermaid":
        text = _mermaid(result)
    elif fmt == "json":
        text = json.dumps(_json(result), indent=2, ensure_ascii=False) + "\n"
    else:
        raise UsageError(f"unknown export format {fmt!r} (use {', '.join(FORMATS)})")
    return Export(
        format=fmt,
        cycle=result.cycle,
        t_ns=result.t_ns,
        command=result.decision.command,
        nodes=len(graph["nodes"]),
        edges=len(graph["edges"]),
        undocumented=sum(1 for e in graph["edges"] if not e.get("documented")),
        text=text,
    )


def _title(result: Explanation) -> str:
    return (
        f"{result.robot} cycle {result.cycle} at {result.log_clock.show(result.t_ns)}: "
        f"{result.decision.command or '?'}"
    )


def _json(result: Explanation) -> dict[str, object]:
    return {
        "robot": result.robot,
        "log": result.path,
        "cycle": result.cycle,
        "t_ns": result.t_ns,
        "command": result.decision.command,
        "causal_graph": result.graph,
        "decision_tree": result.tree,
    }


def _edge_note(edge: EdgeData) -> str:
    level = str(edge.get("level") or "")
    rule = edge.get("rule")
    note = f"{level}: {rule}" if rule else level
    if edge.get("unknown"):
        # the reading is in a recording that could not be read: not known to be missing
        note = f"UNKNOWN {note} (recording not read)"
    elif not edge.get("documented"):
        note = f"MISSING {note}"
    return note


# --- DOT -------------------------------------------------------------------------------------


def _dot_str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


_DOT_SHAPES = {
    "sensor": "cylinder",
    "evidence": "note",
    "entity": "box",
    "belief": "ellipse",
    "action": "doubleoctagon",
    "missing": "box",
}


def _dot(result: Explanation) -> str:
    lines = [
        "digraph trace_decision {",
        f"  label={_dot_str(_title(result))};",
        "  labelloc=t;",
        "  node [fontname=Helvetica, fontsize=10];",
        "  edge [fontname=Helvetica, fontsize=9];",
        "  subgraph cluster_causal {",
        f"    label={_dot_str('causal graph (sensor evidence -> action)')};",
        "    rankdir=BT;",
    ]
    for node in result.graph["nodes"]:
        kind = str(node.get("kind"))
        attrs = [
            f"label={_dot_str(str(node.get('label', node['id'])))}",
            f"shape={_DOT_SHAPES.get(kind, 'box')}",
        ]
        if node.get("missing"):
            attrs += ["style=dashed", "color=red", "fontcolor=red"]
        elif kind == "action":
            attrs += ["style=bold"]
        lines.append(f"    {_dot_str('c:' + node['id'])} [{', '.join(attrs)}];")
    for edge in result.graph["edges"]:
        attrs = [f"label={_dot_str(_edge_note(edge))}"]
        if not edge.get("documented"):
            attrs += ["style=dashed", "color=red", "fontcolor=red"]
        lines.append(
            f"    {_dot_str('c:' + edge['source'])} -> {_dot_str('c:' + edge['target'])} "
            f"[{', '.join(attrs)}];"
        )
    lines.append("  }")
    if result.tree is not None:
        lines += [
            "  subgraph cluster_tree {",
            f"    label={_dot_str('counterfactual decision tree (taken path bold)')};",
        ]
        for node in result.tree["nodes"]:
            leaf = node.get("command") is not None
            attrs = [
                f"label={_dot_str(str(node.get('label') or node['id']))}",
                f"shape={'box' if leaf else 'diamond'}",
            ]
            if node.get("taken"):
                attrs += ['style="bold,filled"', "fillcolor=gray85"]
            lines.append(f"    {_dot_str('t:' + node['id'])} [{', '.join(attrs)}];")
        for edge in result.tree["edges"]:
            attrs = [f"label={_dot_str(str(edge.get('label') or ''))}"]
            if edge.get("taken"):
                attrs += ["style=bold", "penwidth=2.5"]
            lines.append(
                f"    {_dot_str('t:' + edge['source'])} -> {_dot_str('t:' + edge['target'])} "
                f"[{', '.join(attrs)}];"
            )
        lines.append("  }")
    lines.append("}")
    return "\n".join(lines) + "\n"


# --- Mermaid ---------------------------------------------------------------------------------


def _mm_text(text: str) -> str:
    # Mermaid labels go inside double quotes; it has entity codes for what would break them.
    text = text.replace('"', "#quot;").replace("<", "#lt;").replace(">", "#gt;")
    text = text.replace("|", "#124;")  # a bar would end an edge label early
    return re.sub(r"\s+", " ", text)


class _MermaidIds:
    """Short Mermaid node ids (``c0``, ``t5``), one per (prefix, graph node id)."""

    def __init__(self) -> None:
        self.ids: dict[str, str] = {}

    def __call__(self, prefix: str, key: str) -> str:
        full = f"{prefix}:{key}"
        if full not in self.ids:
            self.ids[full] = f"{prefix}{len(self.ids)}"
        return self.ids[full]


def _mermaid(result: Explanation) -> str:
    nid = _MermaidIds()
    lines = ["flowchart BT"]
    missing_nodes, undocumented = _mm_causal(result, nid, lines)
    if result.tree is not None:
        _mm_tree(result.tree, nid, lines)
    lines.append("  classDef missing stroke:#c00,stroke-dasharray:4 3,color:#c00;")
    if missing_nodes:
        lines.append(f"  class {','.join(missing_nodes)} missing;")
    if undocumented:
        lines.append(f"  linkStyle {','.join(map(str, undocumented))} stroke:#c00,color:#c00;")
    return "\n".join(lines) + "\n"


def _mm_causal(
    result: Explanation, nid: _MermaidIds, lines: list[str]
) -> tuple[list[str], list[int]]:
    """The causal graph's subgraph into ``lines``; (placeholder node ids, indexes of the
    undocumented edges), which are styled after every edge is drawn."""
    lines.append(f'  subgraph causal["{_mm_text(_title(result))}: causal graph"]')
    missing_nodes: list[str] = []
    for node in result.graph["nodes"]:
        ident = nid("c", node["id"])
        label = _mm_text(str(node.get("label", node["id"])))
        kind = node.get("kind")
        if kind == "action":
            lines.append(f'    {ident}(["{label}"])')
        elif kind == "sensor":
            lines.append(f'    {ident}[("{label}")]')
        elif kind == "belief":
            lines.append(f'    {ident}("{label}")')
        else:
            lines.append(f'    {ident}["{label}"]')
        if node.get("missing"):
            missing_nodes.append(ident)
    undocumented: list[int] = []
    for index, edge in enumerate(result.graph["edges"]):
        arrow = "-->" if edge.get("documented") else "-.->"
        if not edge.get("documented"):
            undocumented.append(index)
        lines.append(
            f'    {nid("c", edge["source"])} {arrow}|"{_mm_text(_edge_note(edge))}"| '
            f"{nid('c', edge['target'])}"
        )
    lines.append("  end")
    return missing_nodes, undocumented


def _mm_tree(tree: GraphData, nid: _MermaidIds, lines: list[str]) -> None:
    """The counterfactual tree's subgraph into ``lines``, the taken path thick."""
    lines.append('  subgraph tree["counterfactual decision tree (taken path thick)"]')
    lines.append("    direction TB")
    for node in tree["nodes"]:
        ident = nid("t", node["id"])
        label = _mm_text(str(node.get("label") or node["id"]))
        mark = "✔ " if node.get("taken") and node.get("command") else ""
        if node.get("command") is not None:
            lines.append(f'    {ident}["{mark}{label}"]')
        else:
            lines.append(f'    {ident}{{"{label}"}}')
    for edge in tree["edges"]:
        arrow = "==>" if edge.get("taken") else "-->"
        label = _mm_text(str(edge.get("label") or ""))
        middle = f'|"{label}"|' if label else ""
        lines.append(f"    {nid('t', edge['source'])} {arrow}{middle} {nid('t', edge['target'])}")
    lines.append("  end")
