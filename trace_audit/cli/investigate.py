"""trace-audit commands for investigators: explain, why, timeline, info, export.

Each command parses its arguments, calls one library function and renders the result:
rich on a terminal, plain text with ``--plain`` or in a pipe, JSON with ``--json``.
Times are seconds in the log's own clock (``--t 12.3``) or after the log's start
(``--t +12.3``); see ``trace_audit.timeline.TimePoint``.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from itertools import pairwise
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer

from trace_audit.cli.app import (
    EXIT_USAGE,
    JsonOption,
    PlainOption,
    app,
    fail,
    guarded,
    help_text,
    print_json,
)
from trace_audit.cli.render import (
    Column,
    Doc,
    Item,
    Seg,
    emit,
    fmt_duration,
    fmt_t,
)

if TYPE_CHECKING:
    from trace_audit.causal import FactorValue
    from trace_audit.chains import FactorChain
    from trace_audit.explain import Explanation
    from trace_audit.info import LogInfo
    from trace_audit.timeline import ClockRun, Timeline, WhyResult
    from trace_runtime.gaps import Gap

# The library (networkx, pydantic models) is imported inside each command, so that
# ``--help`` and the other command groups start without it.
EXPORT_FORMATS = ("dot", "mermaid", "json")

T = TypeVar("T")

LogArgument = Annotated[
    Path,
    typer.Argument(
        help="A TRACE segment (.mcap), a directory of segments, or a log root (hot/ warm/ cold/).",
        show_default=False,
    ),
]
EvidenceOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--evidence",
        help="An external recording (MCAP file or rosbag2 directory) the log's evidence refs "
        "name; repeat for several.",
        show_default=False,
    ),
]
TimeOption = Annotated[
    str | None,
    typer.Option(
        "--t",
        help="Seconds in the log's clock (12.3), or seconds after the log start (+12.3).",
        show_default=False,
    ),
]

_OK = Seg("✔", "green", "[ok]")
_MISSING = Seg("✘ MISSING", "bold red", "[MISSING]")
_UNREACHED = Seg("·", "dim", "[--]")


def format_value(value: Any, unit: str | None = None) -> str:
    from trace_audit.causal import format_value as fmt

    return fmt(value, unit)


# --- explain -----------------------------------------------------------------------------------

_EXPLAIN_HELP = """Explain the decision in force at a time: what the robot did and why.

Shows the action, rationale, factors with their values, the alternatives and why each
lost, the counterfactuals, the counterfactual decision tree with the taken path, every
factor's causal chain down to the sensor reading (each link documented or MISSING), the
execution record, this decision's ET / ET_partial, whether its seal verifies, and since
when the action has held.

The decision in force at t is the last cycle at or before t. A time outside the log's
range is a usage error (exit 2) that names the range.

[bold]Examples[/bold]:

  trace-audit explain run.mcap --t 12.3

  trace-audit explain logs/amr-7/ --t +600 --plain

  trace-audit explain run.mcap --cycle 4242 --json
"""


@app.command("explain", help=help_text(_EXPLAIN_HELP))
def explain_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    t: TimeOption = None,
    cycle: Annotated[
        int | None,
        typer.Option(
            "--cycle", help="Explain this cycle number instead of a time.", show_default=False
        ),
    ] = None,
    lookback: Annotated[
        float,
        typer.Option(
            "--lookback",
            help="Seconds of log to walk back looking for the cycle "
            "where the current action began.",
        ),
    ] = 600.0,
    evidence: EvidenceOption = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.explain import explain

    result = guarded(
        lambda: explain(log, t=t, cycle=cycle, lookback_s=lookback, evidence=evidence or ())
    )
    emit(result, lambda r: explain_doc(r, lookback), json_out=json_out, plain=plain)


def _external_evidence(doc: Doc, r: Explanation) -> None:
    """Evidence refs into external recordings: resolved (decoded), broken, or not checked."""
    doc.heading("External evidence (recordings the refs name)")
    style = {"resolved": "green", "broken": "bold red", "unresolved": "yellow"}
    for e in r.external_evidence:
        state = {"resolved": "resolved, digest verified", "broken": "BROKEN"}.get(
            e.state, "not checked (recording not given: --evidence)"
        )
        t = fmt_t(e.log_time_ns) if e.log_time_ns is not None else "?"
        doc.line([f"{e.entity}: {e.recording} {e.topic} @ {t}  ", Seg(state, style[e.state])], 2)
        if e.detail and e.state == "broken":
            doc.line(e.detail, 4)
        if e.schema:
            doc.line(e.schema + ": " + ", ".join(f"{k}={v}" for k, v in e.fields), 4)


def explain_doc(r: Explanation, lookback_s: float = 600.0) -> Doc:
    """The explain report as a document."""
    d = r.decision
    doc = Doc()
    when = f"t={fmt_t(r.query_t_ns)}" if r.query_t_ns is not None else f"cycle {r.cycle}"
    doc.title([f"{r.robot} at {when}: ", Seg(d.command or "no action logged", "bold yellow")])
    where = f"{r.path}"
    if r.recovered:
        where += " (recovered from an unfinished segment)"
    if r.query_t_ns is None:
        decided = f"cycle {r.cycle} at {fmt_t(r.t_ns)}"
    elif r.offset_ns == 0:
        decided = f"cycle {r.cycle}, decided exactly at the asked time"
    else:
        decided = (
            f"cycle {r.cycle} at {fmt_t(r.t_ns)}, {fmt_duration(r.offset_ns)} before the asked time"
        )
    rows: list[tuple[str, Any]] = [("Log", where), ("Decision", decided)]
    if r.stale:
        rows.append(
            (
                "Gap",
                Seg(
                    f"no decision was logged in the {fmt_duration(r.offset_ns)} "
                    "before the asked time",
                    "bold red",
                    None,
                ),
            )
        )
    if r.clock_run:
        run = r.clock_run[0] if len(r.clock_run) == 1 else f"{r.clock_run[0]}..{r.clock_run[-1]}"
        rows.append(
            (
                "Clock",
                Seg(
                    f"the robot's clock restarted in this log: read in the run of {run}"
                    + (
                        "; another run may hold a decision at the same time (ask by --cycle)"
                        if r.query_t_ns is not None
                        else ""
                    ),
                    "yellow",
                    None,
                ),
            )
        )
    if d.summary:
        rows.append(("Tier", "warm summary: only what the summary kept is shown"))
    action = d.command or "?"
    extras = [f"{k}={format_value(v)}" for k, v in d.parameters.items()]
    if d.score is not None:
        extras.append(f"score {d.score:.2f}")
    rows.append(
        ("Action", [Seg(action, "bold yellow"), f"  ({', '.join(extras)})" if extras else ""])
    )
    rows.append(("Held", _held_line(r, lookback_s)))
    rationale: list[str | Seg] = [d.rationale if d.rationale is not None else "not logged"]
    if d.truncated:
        rationale.append(Seg("  [TRUNCATED]", "bold red"))
    rows.append(("Rationale", rationale))
    doc.fields(rows)

    doc.heading("Factors")
    if d.factors:
        doc.table(
            [Column("factor"), Column("value", "right"), Column("belief node", wrap=True)],
            [[_factor_name(f, i == 0), f.shown, f.node] for i, f in enumerate(d.factors)],
        )
    else:
        doc.line(Seg("none logged: the decision cannot be traced to evidence", "red"), 2)

    doc.heading("Alternatives (why each lost)")
    if d.alternatives:
        doc.table(
            [Column("command"), Column("score", "right"), Column("rejected because", wrap=True)],
            [
                [a.command, "-" if a.score is None else f"{a.score:.2f}", a.rejected_because]
                for a in d.alternatives
            ],
        )
    else:
        doc.line(Seg("none logged", "red"), 2)

    doc.heading("Counterfactuals")
    if d.counterfactuals:
        for cf in d.counterfactuals:
            now = f"  (now {format_value(cf.value, cf.unit)})" if cf.value is not None else ""
            doc.line([Seg(cf.text, "bold"), now], 2)
    elif d.counterfactuals_none_applicable:
        doc.line("none applicable (declared by the policy)", 2)
    else:
        doc.line(Seg("none logged", "red"), 2)

    if d.tree is not None:
        doc.heading("Counterfactual tree (=> taken path)")
        doc.tree(_tree_item(r))
        for problem in d.tree.problems:
            doc.line(Seg(f"! {problem}", "red"), 2)

    doc.heading("Causal chains (sensor evidence -> action)")
    if not r.chains.factors:
        doc.line(Seg(f"no chain: {r.chains.reason}", "red"), 2)
    for chain in r.chains.factors:
        doc.tree(_chain_item(r, chain))
    if r.external_evidence:
        _external_evidence(doc, r)

    doc.heading("Execution")
    ex = d.execution
    if ex is None:
        doc.line(Seg("not logged", "red"), 2)
    else:
        if ex.channels:
            doc.table(
                [
                    Column("channel"),
                    Column("intended", "right"),
                    Column("actual", "right"),
                    Column("deviation", "right"),
                    Column("unit"),
                ],
                [
                    [
                        c.name,
                        format_value(c.intended),
                        format_value(c.actual),
                        format_value(c.deviation),
                        c.unit,
                    ]
                    for c in ex.channels
                ],
            )
        motion: list[tuple[str, Any]] = (
            [("Intended", _motion(ex.intended)), ("Actual", _motion(ex.actual))]
            if ex.planar or not ex.channels
            else []
        )
        deviation = format_value(ex.deviation)
        if ex.deviation_unit and ex.deviation is not None:
            deviation += f" {ex.deviation_unit}"
        doc.fields(
            [
                *motion,
                ("Deviation", deviation),
                (
                    "Checks",
                    "; ".join(
                        f"{c.rule} {'passed' if c.passed else 'FAILED'}"
                        + (
                            f" ({format_value(c.value)} vs limit {format_value(c.limit)})"
                            if c.value is not None and c.limit is not None
                            else ""
                        )
                        for c in ex.checks
                    )
                    or "none logged",
                ),
                ("Flags", Seg(", ".join(ex.problems), "bold red") if ex.problems else "none"),
                *([("Scenario", ex.scenario)] if ex.scenario else []),
            ]
        )

    doc.heading("Auditability of this decision")
    s = r.scores
    traceable = sum(1 for c in r.chains.factors if c.traceable)
    score_rows: list[tuple[str, Any]] = [
        (
            "ET",
            f"{s.et:.2f}  ({traceable} of {len(r.chains.factors)} factors traced to "
            "a sensor reading)",
        ),
        ("ET_partial", f"{s.et_partial:.2f}"),
        ("DR", f"{s.dr:.0f}"),
        ("TCS", f"{s.tcs:.2f}"),
    ]
    doc.fields(score_rows)
    for problem in s.problems:
        doc.line(Seg(f"- {problem}", "yellow"), 2)

    doc.heading("Integrity")
    seal = r.seal
    if seal.verified:
        status = Seg("✔ seal verifies", "bold green", "[ok] seal verifies")
    elif seal.in_flight:
        # The normal end of a crashed segment (PROFILE §8): unverifiable, not a failed check.
        status = Seg("⚠ UNSEALED", "bold yellow", "[UNSEALED]")
    elif not seal.sealed:
        status = Seg("✘ not sealed", "bold red", "[FAILED] not sealed")
    else:
        status = Seg("✘ seal does NOT verify", "bold red", "[FAILED] seal does not verify")
    rows = [("Seal", [status, f" ({seal.state})"])]
    if seal.sealed:
        if seal.digests_ok is None:
            layers = "nothing to compare (no layer messages kept)"
        elif seal.digests_ok:
            layers = "every logged layer matches its seal digest"
        else:
            layers = "MISMATCH: " + ", ".join(
                [
                    *seal.mismatched,
                    *(f"{t} not sealed" for t in seal.unnamed),
                    *(f"{t} missing" for t in seal.absent),
                ]
            )
        if seal.summarised:
            layers += f"; {len(seal.summarised)} layers summarised (warm tier), not comparable"
        rows.append(("Layers", layers))
        if seal.evidence_checked or seal.evidence_mismatch:
            evidence = f"{seal.evidence_checked} evidenced sensor readings checked"
            if seal.evidence_mismatch:
                evidence += "; DIFFER: " + ", ".join(seal.evidence_mismatch)
            rows.append(("Evidence", evidence))
        link = "matches" if seal.prev_ok else "does NOT match"
        rows.append(("Chain", f"prev {link} {seal.prev_source}"))
        if seal.dropped_before:
            rows.append(
                (
                    "Dropped",
                    Seg(
                        f"{seal.dropped_before} cycles dropped just before "
                        "this one (declared by the seal)",
                        "yellow",
                    ),
                )
            )
    doc.fields(rows)
    for problem in seal.problems:
        doc.line(Seg(f"- {problem}", "yellow" if seal.in_flight else "red"), 2)
    return doc


def _held_line(r: Explanation, lookback_s: float) -> Any:
    h = r.held
    span = fmt_duration(r.t_ns - h.since_t_ns)
    if h.cycles <= 1 and h.bound == "change":
        return f"new at this cycle (before: {h.previous or '?'}, cycle {h.previous_cycle})"
    base = f"since {fmt_t(h.since_t_ns)} (cycle {h.since_cycle}; {span}, {h.cycles} cycles)"
    if h.bound == "change":
        return f"{base}; before it: {h.previous or '?'} (cycle {h.previous_cycle})"
    if h.bound == "lookback":
        return (
            f"at least {base}; stopped looking after {fmt_duration(int(lookback_s * 1e9))}"
            " (--lookback)"
        )
    return f"at least {base}: the log starts there"


def _factor_name(f: FactorValue, leading: bool) -> Any:
    return [f.label, Seg(" (leading)", "dim")] if leading else f.label


def _motion(m: tuple[float | None, float | None]) -> str:
    lin, ang = m
    return f"{format_value(lin)} m/s, {format_value(ang)} rad/s"


def _tree_item(r: Explanation) -> Item:
    tree = r.tree
    assert tree is not None
    nodes = {n["id"]: n for n in tree["nodes"]}
    children: dict[str, list[Mapping[str, Any]]] = {}
    for edge in tree["edges"]:
        children.setdefault(edge["source"], []).append(edge)
    root_id = tree["graph"].get("root")

    def line(node_id: str, label: str) -> list[Any]:
        node = nodes.get(node_id, {"label": node_id})
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

    seen: set[str] = set()

    def build(node_id: str, label: str, depth: int) -> Item:
        item = Item(line(node_id, label))
        if node_id in seen:
            return item  # a malformed tree with a cycle: show the node once
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


_MAX_TREE_DEPTH = 12
"""Levels of a counterfactual tree drawn in a terminal; deeper ones are in ``--json``."""

_LEVEL_NAMES = {
    "sensor_reading": "sensor reading",
    "evidence_ref": "evidence ref",
    "entity": "perception",
    "belief_path": "belief path",
    "factor_node": "factor",
}


def _chain_item(r: Explanation, chain: FactorChain) -> Item:
    graph = r.graph
    labels = {n["id"]: str(n.get("label", n["id"])) for n in graph["nodes"]}
    mine = [e for e in graph["edges"] if chain.node in e.get("factors", ())]
    by_level: dict[str, list[Mapping[str, Any]]] = {}
    for edge in mine:
        by_level.setdefault(str(edge.get("level")), []).append(edge)
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
    kinds = {n["id"]: n.get("belief_kind") for n in graph["nodes"]}
    # The belief entity node mirrors the perception entity: one mention is enough here.
    path = [p for p in _chain_path(mine) if kinds.get(p) != "entity"]
    if path:
        root.add(Seg(" -> ".join(labels.get(p, p) for p in path), "dim"))
    for link in reversed(chain.links):
        edges = by_level.get(link.level, [])
        name = _LEVEL_NAMES.get(link.level, link.level)
        if link.level == "belief_path" and link.documented:
            what = _belief_path_text(graph, link.ref)
        elif link.level == "factor_node":
            what = f"{labels.get('belief:' + chain.node, chain.node)} -> {r.decision.command}"
        elif edges:
            what = labels.get(edges[0]["source"], link.ref)
        else:
            what = link.ref
        line: list[Any]
        if link.documented:
            line = [_OK, f" {name}: {what}"]
        elif link.detail.startswith("not reached"):
            line = [_UNREACHED, f" {name}: ", Seg("not reached (the chain breaks above)", "dim")]
        else:
            # a placeholder label says nothing the detail does not: show the logged part only
            logged = "" if what.startswith("? ") else f"{what} "
            line = [_MISSING, f" {name}: {logged}", Seg(f"({link.detail})", "red")]
        root.add(line)
    return root


def _belief_path_text(graph: Mapping[str, Any], ref: str) -> str:
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


def _chain_path(edges: Sequence[Mapping[str, Any]]) -> list[str]:
    """The chain's nodes from the bottom (sensor or placeholder) up to the action."""
    succ = {e["source"]: e["target"] for e in edges}
    targets = set(succ.values())
    starts = [s for s in succ if s not in targets]
    if len(starts) != 1:
        return []
    path = [starts[0]]
    while path[-1] in succ and len(path) <= len(edges):
        path.append(succ[path[-1]])
    return path


# --- why ---------------------------------------------------------------------------------------

_WHY_HELP = """Why did the robot take an action? Every transition into it, with the reason.

A transition is a cycle whose command is ACTION while the previous logged cycle's was not.
For each: when, what it changed from, how long it held, the rationale, the factors with
their values (the leading one first), the counterfactuals and any execution flags. With
--t, only the transition that led to the state at that time. ACTION is matched without
regard to case; one the log never shows is a usage error (exit 2) listing those it does.

[bold]Examples[/bold]:

  trace-audit why run.mcap --action STOP

  trace-audit why run.mcap --action STOP --t 25

  trace-audit why logs/amr-7/ --action reroute --json
"""


@app.command("why", help=help_text(_WHY_HELP))
def why_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    action: Annotated[
        str, typer.Option("--action", help="The command to explain, e.g. STOP.", show_default=False)
    ],
    t: TimeOption = None,
    all_: Annotated[
        bool, typer.Option("--all", help="Every transition in the log (the default without --t).")
    ] = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    if all_ and t is not None:
        fail("give either --t or --all, not both", EXIT_USAGE)
    from trace_audit.timeline import why

    result = guarded(lambda: why(log, action, t=t))
    emit(result, why_doc, json_out=json_out, plain=plain)


def why_doc(r: WhyResult) -> Doc:
    doc = Doc()
    n = len(r.transitions)
    scope = (
        f"in force at t={fmt_t(r.t_ns)}"
        if r.t_ns is not None
        else (f"{n} transition{'s' if n != 1 else ''}")
    )
    doc.title([f"Why {r.action}? ", f"{r.robot}, {scope}"])
    if r.recovered:
        doc.line("(log recovered from an unfinished segment)")
    for i, tr in enumerate(r.transitions, 1):
        doc.heading(f"#{i}  t={fmt_t(tr.t_ns)}  cycle {tr.cycle}")
        before = (
            f"{tr.previous} (cycle {tr.previous_cycle})"
            if tr.previous is not None
            else "nothing: the log starts here"
        )
        if tr.unlogged_before:
            n = tr.unlogged_before
            before += f"; {n} cycle{'s' if n != 1 else ''} in between not logged"
        held = fmt_duration(tr.held_ns)
        if tr.ongoing:
            until = "and still holds at the end of the log"
        else:
            until = f"until {fmt_t(tr.ended_t_ns or 0)}, then {tr.next_command or '?'}"
        rows: list[tuple[str, Any]] = [
            ("Changed from", before),
            ("Held", f"{held} ({tr.held_cycles} cycles) {until}"),
        ]
        rationale: list[Any] = [tr.rationale if tr.rationale is not None else "not logged"]
        if tr.truncated:
            rationale.append(Seg("  [TRUNCATED]", "bold red"))
        rows.append(("Reason", rationale))
        if tr.factors:
            lead = tr.factors[0]
            rows.append(
                (
                    "Leading factor",
                    [Seg(f"{lead.label} = {lead.shown}", "bold"), f"  ({lead.node})"],
                )
            )
            others = "; ".join(f"{f.label} = {f.shown}" for f in tr.factors[1:])
            if others:
                rows.append(("Other factors", others))
        else:
            rows.append(("Factors", Seg("none logged", "red")))
        if tr.counterfactuals:
            rows.append(("What-ifs", "; ".join(c.text for c in tr.counterfactuals)))
        rows.append(("Flags", Seg(", ".join(tr.flags), "bold red") if tr.flags else "none"))
        doc.fields(rows)
    if r.t_ns is None and len(r.actions_present) > 1:
        doc.heading("Cycles per command")
        doc.line(", ".join(f"{c}: {k}" for c, k in r.actions_present.items()), 2)
    return doc


# --- timeline ----------------------------------------------------------------------------------

_TIMELINE_HELP = """The decisions over time: a row per decision change, with the leading
factor and execution flags, and the gaps where no cycle was logged.

Each row is a stretch of cycles with one command: when it began, how long it held, the
leading factor (the first the rationale names) and the flags raised while it held.
--every gives a row per cycle instead.

[bold]Examples[/bold]:

  trace-audit timeline run.mcap

  trace-audit timeline run.mcap --from 10 --to 20 --every

  trace-audit timeline logs/amr-7/ --from +3600 --to +3900 --json
"""


@app.command("timeline", help=help_text(_TIMELINE_HELP))
def timeline_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    start: Annotated[
        str | None,
        typer.Option(
            "--from",
            help="Start of the window (seconds, or +seconds after the log "
            "start). Default: the log start.",
            show_default=False,
        ),
    ] = None,
    end: Annotated[
        str | None,
        typer.Option(
            "--to", help="End of the window (same forms). Default: the log end.", show_default=False
        ),
    ] = None,
    every: Annotated[bool, typer.Option("--every", help="A row per cycle.")] = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.timeline import timeline

    result = guarded(lambda: timeline(log, start=start, end=end, every=every))
    emit(result, timeline_doc, json_out=json_out, plain=plain)


def timeline_doc(r: Timeline) -> Doc:
    doc = Doc()
    doc.title(f"{r.robot}: {fmt_t(r.start_ns)} .. {fmt_t(r.end_ns)}")
    changes = r.changes
    doc.line(
        f"{r.cycles} cycles, {changes} decision change{'s' if changes != 1 else ''}, "
        f"{len(r.gaps)} gap{'s' if len(r.gaps) != 1 else ''}"
        + ("; recovered from an unfinished segment" if r.recovered else "")
    )
    if not r.clock_runs:
        _timeline_table(doc, r, list(r.rows), list(r.gaps))
        return doc
    # The clock restarted: each run is its own sequence (times start again lower), so the
    # runs are shown one after the other, never merged by time.
    doc.line(
        Seg(
            f"The robot's clock restarted {len(r.clock_runs) - 1} time(s) in this log: each "
            "run of its clock is shown on its own.",
            "yellow",
        )
    )
    for number, run in enumerate(r.clock_runs):
        cycles = (
            f"cycles {run.first_cycle}..{run.last_cycle}"
            if run.first_cycle is not None
            else "no cycle in the window"
        )
        shown = run.segments[0] if len(run.segments) == 1 else f"{run.segments[0]}.."
        doc.line(f"clock run {number + 1} of {len(r.clock_runs)}: {cycles} ({shown})")
        in_run = [g for g in r.gaps if _in_run(g.after_cycle, run)]
        _timeline_table(doc, r, [row for row in r.rows if row.run == number], in_run)
    return doc


def _in_run(cycle: int, run: ClockRun) -> bool:
    first, last = run.first_cycle, run.last_cycle
    return first is not None and last is not None and first <= cycle <= last


def _timeline_table(doc: Doc, r: Timeline, rows: list[Any], gaps: list[Gap]) -> None:
    events: list[tuple[int, int, list[Any]]] = []
    for row in rows:
        lead = f"{row.leading.label} = {row.leading.shown}" if row.leading else "-"
        flags = ", ".join(f"{k} x{v}" if v > 1 else k for k, v in row.flag_counts.items())
        what: list[Any] = [lead]
        if row.max_deviation is not None:
            what.append(f"; max deviation {format_value(row.max_deviation)} {row.deviation_unit}")
        if flags:
            what.append(Seg(f"; flags: {flags}", "bold red"))
        if row.scenario:
            what.append(Seg(f" [{row.scenario}]", "dim"))
        command = row.command or "?"
        held = fmt_duration(row.held_ns)
        events.append(
            (
                row.t_ns,
                0,
                [
                    f"{row.t_ns / 1e9:.3f}",
                    str(row.cycle),
                    Seg(command, "bold yellow" if row.previous != row.command else ""),
                    f"{held} / {row.cycles}" if not r.every else held,
                    what,
                ],
            )
        )
    for gap in gaps:
        events.append((gap.after_t_ns, 1, _gap_row(gap)))
    events.sort(key=lambda e: (e[0], e[1]))
    doc.table(
        [
            Column("t (s)", "right"),
            Column("cycle", "right"),
            Column("decision"),
            Column("held / cycles" if not r.every else "held", "right"),
            Column("leading factor, flags", wrap=True),
        ],
        [e[2] for e in events],
    )


def _gap_row(gap: Gap) -> list[Any]:
    """A timeline row for a gap: how long beyond the period, the cycles it would have held,
    and what the seal after it declares."""
    declared = gap.declared_dropped
    said = "" if declared is None else f", {declared} declared dropped by the seal after it"
    return [
        f"{gap.after_t_ns / 1e9:.3f}",
        "",
        Seg("GAP", "bold red"),
        fmt_duration(gap.gap_ns),
        Seg(
            f"no cycle between {gap.after_cycle} and {gap.before_cycle} "
            f"(~{gap.missing_cycles} missing{said})",
            "red",
        ),
    ]


# --- info --------------------------------------------------------------------------------------

_INFO_HELP = """What a log holds: robot, time range, cycles, segments and tiers, channels,
dropped cycles and gaps, and whether each segment was finished or recovered.

Dropped cycles and gaps need every seal (a scan of the log); --quick answers from the
segment summaries alone.

[bold]Examples[/bold]:

  trace-audit info run.mcap

  trace-audit info logs/amr-7/ --quick --json
"""


@app.command("info", help=help_text(_INFO_HELP))
def info_command(
    log: LogArgument,
    quick: Annotated[
        bool, typer.Option("--quick", help="Skip the scan of every seal (no drops or gaps).")
    ] = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.info import log_info

    result = guarded(lambda: log_info(log, scan=not quick))
    emit(result, info_doc, json_out=json_out, plain=plain)


def _size(n: int) -> str:
    for unit, scale in (("GB", 1 << 30), ("MB", 1 << 20), ("kB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"


def info_doc(r: LogInfo) -> Doc:
    doc = Doc()
    doc.title(f"{', '.join(r.robots)}: {r.path}")
    state = (
        Seg("RECOVERED (a segment has no summary: read by scan)", "bold yellow")
        if r.recovered
        else Seg("finished", "green")
        if r.finished
        else "unfinished"
    )
    tiers = ", ".join(f"{k} x{v}" for k, v in sorted(r.tiers.items()))
    period = f"{r.period_ns / 1e6:g} ms" if r.period_ns else "?"
    rows: list[tuple[str, Any]] = [
        ("Time range", f"{fmt_t(r.start_ns)} .. {fmt_t(r.end_ns)} ({fmt_duration(r.duration_ns)})"),
        (
            "Cycles",
            f"{r.cycles:,} (nominal period {period})"
            + ("" if r.scanned else "; sealed cycles per the summaries"),
        ),
        ("Segments", f"{len(r.segments)} ({tiers})"),
        ("State", state),
    ]
    if r.scanned:
        dropped = r.dropped or 0
        rows.append(
            (
                "Dropped",
                Seg(f"{dropped:,} cycles (sum of the seals' dropped)", "yellow" if dropped else ""),
            )
        )
        rows.append(
            (
                "Gaps",
                Seg(
                    f"{len(r.gaps)}, {fmt_duration(r.gap_ns)} beyond the period",
                    "yellow" if r.gaps else "",
                ),
            )
        )
    else:
        rows.append(("Dropped, gaps", "not counted (--quick)"))
    doc.fields(rows)
    doc.heading("Segments")
    doc.table(
        [
            Column("file", wrap=True),
            Column("tier"),
            Column("time (s)"),
            Column("cycles"),
            Column("size", "right"),
            Column("state"),
        ],
        [
            [
                Path(s.path).name,
                s.tier,
                f"{s.start_ns / 1e9:.1f}..{s.end_ns / 1e9:.1f}",
                f"{s.first_cycle}..{s.last_cycle}" if s.first_cycle is not None else "-",
                _size(s.bytes),
                Seg("recovered", "yellow") if s.recovered else "ok",
            ]
            for s in r.segments
        ],
    )
    doc.heading("Channels")
    doc.table(
        [Column("topic", wrap=True), Column("messages", "right")],
        [[topic, str(n)] for topic, n in r.channels.items()],
    )
    if r.gaps:
        doc.heading("Gaps")
        shown = r.gaps[:20]
        doc.table(
            [
                Column("after cycle", "right"),
                Column("from (s)", "right"),
                Column("beyond period", "right"),
                Column("missing", "right"),
                Column("declared", "right"),
            ],
            [
                [
                    str(g.after_cycle),
                    f"{g.after_t_ns / 1e9:.3f}",
                    fmt_duration(g.gap_ns),
                    f"~{g.missing_cycles}",
                    "?" if g.declared_dropped is None else str(g.declared_dropped),
                ]
                for g in shown
            ],
        )
        if len(r.gaps) > len(shown):
            doc.line(f"... and {len(r.gaps) - len(shown)} more (--json lists them all)", 2)
    return doc


# --- export ------------------------------------------------------------------------------------

_EXPORT_HELP = """Export a decision's causal graph and counterfactual tree for a report.

dot (Graphviz), mermaid (Markdown-friendly) or json. Undocumented links are dashed and
labelled MISSING; the tree's taken path is bold.

[bold]Examples[/bold]:

  trace-audit export run.mcap --t 12.3 --format dot --out stop.dot

  trace-audit export run.mcap --t 12.3 --format mermaid >> incident.md

  trace-audit export run.mcap --cycle 4242 --format json
"""


@app.command("export", help=help_text(_EXPORT_HELP))
def export_command(
    log: LogArgument,
    *,
    t: TimeOption = None,
    cycle: Annotated[
        int | None,
        typer.Option(
            "--cycle", help="Export this cycle number instead of a time.", show_default=False
        ),
    ] = None,
    fmt: Annotated[
        str, typer.Option("--format", help=f"One of {', '.join(EXPORT_FORMATS)}.")
    ] = "dot",
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write to this file instead of stdout.", show_default=False),
    ] = None,
    json_out: Annotated[
        bool,
        typer.Option(
            "--json",
            help="Print the export and its counts (cycle, nodes, edges, undocumented links) "
            "as one JSON object.",
        ),
    ] = False,
    plain: PlainOption = False,  # the export is plain text already; accepted like elsewhere
) -> None:
    from trace_audit.export import export_decision

    result = guarded(lambda: export_decision(log, t=t, cycle=cycle, fmt=fmt))
    if json_out and out is None:
        print_json(result)
        return
    if out is None:
        sys.stdout.write(result.text)
        return
    try:
        out.write_text(result.text, encoding="utf-8")
    except OSError as err:
        fail(f"{out}: cannot write ({err.strerror or err})", EXIT_USAGE)
    sys.stderr.write(
        f"trace-audit: wrote {out} ({result.format}: cycle {result.cycle}, "
        f"{result.nodes} nodes, {result.edges} edges, {result.undocumented} undocumented)\n"
    )
