"""The report's sections on the decision itself: what the robot did, why, on what evidence,
what else it weighed, and how it executed.

Each ``*_section`` takes the ``ReportData`` and returns the section's HTML body; every
string from the log passes through ``html.escape``.
"""

from __future__ import annotations

from html import escape

from trace_audit.causal import format_value
from trace_audit.incident.data import ReportData
from trace_audit.incident.drawing import MAX_ENTITIES, MAX_FACTORS, MAX_GRAPH_NODES
from trace_audit.incident.graph_figures import causal_figure, tree_figure
from trace_audit.incident.markup import (
    command_badge,
    html_fields,
    html_figure,
    html_problems,
    html_table,
)
from trace_audit.incident.scene import scene_figure
from trace_audit.incident.time_figures import execution_figure, factors_figure
from trace_audit.incident.window import execution_channels

__all__ = [
    "causal_section",
    "counterfactuals_section",
    "execution_section",
    "factors_section",
    "scene_section",
    "summary_section",
]


def _clock_line(data: ReportData) -> str:
    """The decision's time as the log's clock shows it: on a wall clock the UTC moment and
    the seconds since the log's start, never raw seconds since 1970."""
    e = data.explanation
    return f"{escape(e.log_clock.show(e.t_ns))} in the log's clock ({escape(data.session.clock)})"


def _evidence_status(state: str, problem: str) -> str:
    """An evidence item's status after its ref: nothing when it resolves, the problem in red
    when it fails, in amber as unknown when its recording could not be read."""
    if state == "resolved":
        return ""
    kind = "warn" if state == "unresolved" else "bad"
    said = f"not checked, unknown: {problem}" if state == "unresolved" else problem
    return f' <span class="{kind}">{escape(said)}</span>'


def summary_section(data: ReportData) -> str:
    e, d, s = data.explanation, data.decision, data.session
    held = e.held
    if held.bound == "change" and held.cycles <= 1:
        since = f"new at this cycle; before it the robot was told {escape(held.previous or '?')}"
    else:
        lead = "at least " if held.at_least else ""
        since = (
            f"{lead}since {escape(e.log_clock.show(held.since_t_ns))} (cycle {held.since_cycle}, "
            f"{held.cycles} cycles)"
        )
        if held.previous:
            since += f"; before it: {escape(held.previous)}"
    asked = (
        f"cycle {e.cycle} (asked for cycle {e.query_cycle})"
        if e.query_t_ns is None
        else f"cycle {e.cycle}, the decision in force at the asked time "
        f"{e.log_clock.show(e.query_t_ns)}"
    )
    leading = d.leading
    rows = [
        ("Robot", escape(e.robot)),
        ("Time", _clock_line(data)),
        ("Decision", asked),
        ("Action", command_badge(d.command) + _parameters(d.parameters)),
        ("Held", since),
        (
            "Leading factor",
            escape(f"{leading.label} = {leading.shown}") if leading else "none logged",
        ),
        ("Software", escape(s.software_version or "not recorded")),
        ("Policy", escape(s.policy_version or "not recorded")),
        (
            "Window shown",
            f"{e.log_clock.show(data.start_ns)} to {e.log_clock.show(data.end_ns)} "
            f"({len(data.samples)} cycles; "
            f"asked for {data.window_s:g} s)",
        ),
    ]
    notes = []
    if e.recovered:
        notes.append(
            "This log was recovered from a segment the robot did not close (it crashed or "
            "lost power): every complete record was read."
        )
    if e.stale:
        notes.append(
            f"No decision was logged in the {e.offset_ns / 1e9:.3f} s before the asked time."
        )
    if data.not_retained:
        notes.append(
            "This cycle is a warm-tier summary. Not retained: "
            + "; ".join(data.not_retained)
            + ". Sections below show what the summary kept."
        )
    note_html = "".join(f'<p class="note bad">{escape(n)}</p>' for n in notes)
    return html_fields(rows) + note_html


def _parameters(parameters: dict[str, float]) -> str:
    if not parameters:
        return ""
    shown = ", ".join(f"{k} = {format_value(v)}" for k, v in parameters.items())
    return f' <span class="muted">({escape(shown)})</span>'


def factors_section(data: ReportData) -> str:
    d = data.decision
    rows = [
        [
            escape(f.label) + (' <span class="muted">(leading)</span>' if i == 0 else ""),
            escape(f.shown),
            escape(f.node),
        ]
        for i, f in enumerate(d.factors)
    ]
    table = (
        html_table(["factor", "value at the decision", "belief node"], rows, {1})
        if rows
        else '<p class="bad">No factors logged: the decision cannot be traced to evidence.</p>'
    )
    caption = (
        "Each factor the decision names, in every cycle of the window (dots); dashed lines "
        "are the thresholds its counterfactuals name; the background colour is the command "
        "in force; the black line marks the decision explained."
    )
    if len(d.factors) > MAX_FACTORS:
        caption += f" The first {MAX_FACTORS} of {len(d.factors)} factors are plotted."
    return table + html_figure(factors_figure(data), caption)


def scene_section(data: ReportData) -> str:
    if not data.entities:
        kept = "" if data.entities_retained else " (perception not retained in this tier)"
        return f'<p class="note">No perceived entities logged{escape(kept)}.</p>'
    rows = []
    for entity in data.entities[:MAX_ENTITIES]:
        evidence = (
            "<br>".join(
                escape(f"{ev.sensor} (w={format_value(ev.weight)}) {ev.region}; ref {ev.ref}")
                + _evidence_status(ev.state, ev.problem)
                for ev in entity.evidence
            )
            or '<span class="bad">no evidence logged</span>'
        )
        evidence = (
            f'<span data-entity="{escape(entity.id)}" '
            f'data-evidence="{entity.evidence_state}"></span>{evidence}'
        )
        where = (
            f"({entity.x:.2f}, {entity.y:.2f}) {escape(entity.frame)}"
            if entity.x is not None and entity.y is not None
            else "not logged"
        )
        conf = f"{entity.confidence:.3f}" if entity.confidence is not None else "?"
        rows.append(
            [
                escape(entity.id),
                escape(entity.cls),
                conf,
                where,
                escape(entity.distance or "-"),
                evidence,
            ]
        )
    caption = (
        "Top-down view of the robot and what it perceived at the decision, in the frame the "
        "poses were logged in; dotted lines join the robot to each entity whose distance the "
        "belief graph holds. Hollow red marks: no evidence of that entity resolves to a "
        "logged sensor reading. Hollow amber marks: its evidence is in a recording that "
        "could not be read, so whether it resolves is unknown."
    )
    if data.robot is None:
        caption += " The robot did not log its own pose (robot_pose), so it is not drawn."
    if len(data.entities) > MAX_ENTITIES:
        caption += (
            f" Shown: the first {MAX_ENTITIES} of {len(data.entities)} entities "
            "(explain --json lists all)."
        )
    return html_figure(scene_figure(data), caption) + html_table(
        [
            "entity",
            "class",
            "confidence",
            "position (m)",
            "distance",
            "evidence (sensor, region, ref)",
        ],
        rows,
        {2},
    )


def causal_section(data: ReportData) -> str:
    chains = data.explanation.chains
    rows = []
    for chain in chains.factors:
        broken = chain.missing
        status = (
            '<span class="ok">traceable</span>'
            if chain.traceable
            else f'<span class="bad">breaks at {escape(broken.level if broken else "?")}: '
            f"{escape(broken.detail if broken else '')}</span>"
        )
        rows.append(
            [escape(chain.name or chain.node), f"{chain.depth}/{chain.expected_depth}", status]
        )
    table = html_table(["factor", "documented depth", "chain"], rows, {1})
    if chains.reason:
        table += f'<p class="bad">{escape(chains.reason)}</p>'
    caption = (
        "From the sensor reading (left) through the evidence, the perceived entity and the "
        "belief graph to the factor and the action (right). A dashed red link is one the log "
        "does not document, with the reason."
    )
    if len(data.explanation.graph["nodes"]) > MAX_GRAPH_NODES:
        caption = (
            f"The graph has {len(data.explanation.graph['nodes'])} nodes, more than the "
            f"{MAX_GRAPH_NODES} drawn here: the table below and "
            "trace-audit export --format dot show it."
        )
    return html_figure(causal_figure(data), caption) + table + _external(data)


def _external(data: ReportData) -> str:
    """The decision's evidence refs into external recordings (e.g. a rosbag2 bag): resolved
    and decoded, broken, or not checked because the recording was not given."""
    refs = data.explanation.external_evidence
    if not refs:
        return ""
    state = {
        "resolved": '<span class="ok">resolved, digest matches</span>',
        "broken": '<span class="bad">broken</span>',
        "unresolved": '<span class="unknown">not checked, unknown</span>',
    }
    clock = data.explanation.log_clock
    rows = [
        [
            f'<span data-external="{escape(e.entity)}" data-evidence="{e.state}"></span>'
            + escape(e.entity),
            escape(
                f"{e.recording} {e.topic} @ "
                + ("?" if e.log_time_ns is None else clock.show(e.log_time_ns))
            ),
            state.get(e.state, escape(e.state)) + (f" ({escape(e.detail)})" if e.detail else ""),
            escape(e.schema or ""),
        ]
        for e in refs
    ]
    return "<h3>Evidence in external recordings</h3>" + html_table(
        ["entity", "message", "status", "type"], rows, set()
    )


def counterfactuals_section(data: ReportData) -> str:
    d = data.decision
    alternatives = (
        html_table(
            ["command", "score", "why it lost"],
            (
                [
                    command_badge(a.command),
                    "-" if a.score is None else f"{a.score:.2f}",
                    escape(a.rejected_because),
                ]
                for a in d.alternatives
            ),
            {1},
        )
        if d.alternatives
        else '<p class="bad">No alternatives logged.</p>'
    )
    if d.counterfactuals:
        items = "".join(
            f"<li><strong>{escape(cf.text)}</strong>"
            + (
                f' <span class="muted">(now {escape(format_value(cf.value, cf.unit))})</span>'
                if cf.value is not None
                else ""
            )
            + "</li>"
            for cf in d.counterfactuals
        )
        what_if = f'<ul id="what-ifs">{items}</ul>'
    elif d.counterfactuals_none_applicable:
        what_if = "<p>None applicable (declared by the policy).</p>"
    else:
        what_if = '<p class="bad">No counterfactuals logged.</p>'
    tree = tree_figure(data)
    tree_html = (
        html_figure(tree, "The policy's decision tree; the path taken is bold green.")
        if tree is not None
        else '<p class="note">No tree drawn: none logged, not a tree, or over '
        f"{MAX_GRAPH_NODES} nodes (explain shows it).</p>"
    )
    if d.tree is not None:
        tree_html += html_problems(d.tree.problems)
    return (
        "<h3>What would have changed the decision</h3>"
        + what_if
        + "<h3>The alternatives, and why each lost</h3>"
        + alternatives
        + "<h3>The counterfactual tree</h3>"
        + tree_html
    )


def execution_section(data: ReportData) -> str:
    ex = data.decision.execution
    if ex is None:
        return '<p class="bad">No execution record logged for this decision.</p>'
    rows = [
        (name, escape(f"intended {format_value(i)}, actual {format_value(a)}"))
        for name, (i, a) in execution_channels(ex).items()
    ]
    rows.append(("Deviation", escape(format_value(ex.deviation))))
    checks = "<br>".join(
        ('<span class="ok">passed</span> ' if c.passed else '<span class="bad">FAILED</span> ')
        + escape(
            c.rule
            + (
                f" ({format_value(c.value)} vs limit {format_value(c.limit)})"
                if c.value is not None and c.limit is not None
                else ""
            )
            + (f": {c.detail}" if c.detail else "")
        )
        for c in ex.checks
    )
    rows.append(("Checks", checks or "none logged"))
    rows.append(
        (
            "Flags",
            f'<span class="bad">{escape(", ".join(ex.problems))}</span>' if ex.problems else "none",
        )
    )
    failing = sum(1 for s in data.samples if s.failed_checks)
    caption = (
        f"Intended (dashed) and actual motion over the window; deviation below, a cross "
        f"where a compliance check failed ({failing} of {len(data.samples)} cycles)."
    )
    return html_fields(rows) + html_figure(execution_figure(data), caption)
