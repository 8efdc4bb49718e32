"""``trace-audit explain``: the decision in force at a time, what the robot did and why.

Parses its arguments, calls ``trace_audit.explanation.explain`` and renders the typed
``Explanation``, a section per question (what was decided, on which factors, against which
alternatives, traced to which sensor readings, executed how, scored and sealed how): rich
on a terminal, plain text with ``--plain`` or in a pipe, JSON with ``--json``. The causal
chains and the counterfactual tree are drawn by ``trace_audit.cli.explain_graphs``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import app, guarded, help_text
from trace_audit.cli.doc import Column, Doc, Line, Seg, fmt_duration, fmt_t, fmt_value
from trace_audit.cli.explain_evidence import channel_evidence, external_evidence, sensors
from trace_audit.cli.explain_graphs import chain_item, tree_item
from trace_audit.cli.options import (
    EvidenceOption,
    JsonOption,
    LogArgument,
    PlainOption,
    RobotsOption,
    TimeOption,
    cycle_option,
)
from trace_audit.cli.output import emit

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from trace_audit.causal import FactorValue
    from trace_audit.explanation import Explanation

__all__ = ["explain_command", "explain_doc"]

_EXPLAIN_HELP = """Explain the decision in force at a time: what the robot did and why.

Shows the action, rationale, factors with their values, the alternatives and why each
lost, the counterfactuals, the counterfactual decision tree with the taken path, every
factor's causal chain down to the sensor reading (each link documented or MISSING), each
message cited in a recording decoded (in full with --json) with the region the decision
cited, the sensors used and unavailable with the age of each cited reading, the execution
record (and the message each actuator channel was read from), this decision's ET /
ET_partial, whether its seal verifies, and since when the action has held.

The decision in force at t is the last cycle at or before t. A time outside the log's
range is a usage error (exit 2) that names the range. In a root of several robots, --robot
names the robot; without it the time must name one robot's decision, or the command stops
(exit 2) listing the robots that have one then.

[bold]Examples[/bold]:

  trace-audit explain run.mcap --t 12.3

  trace-audit explain logs/amr-7/ --t +600 --plain

  trace-audit explain run.mcap --cycle 4242 --json

  trace-audit explain fleet/ --robot amr-2 --t 2026-05-04T06:04:25Z
"""


@app.command("explain", help=help_text(_EXPLAIN_HELP))
def explain_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    t: TimeOption = None,
    cycle: Annotated[int | None, cycle_option("Explain")] = None,
    robot: RobotsOption = None,
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
    from trace_audit.explanation import explain

    result = guarded(
        lambda: explain(
            log,
            t=t,
            cycle=cycle,
            lookback_s=lookback,
            evidence=evidence or (),
            robots=robot or (),
        )
    )
    emit(result, lambda r: explain_doc(r, lookback), json_out=json_out, plain=plain)


def explain_doc(r: Explanation, lookback_s: float = 600.0) -> Doc:
    """The explain report as a document."""
    doc = Doc()
    when = (
        f"t={fmt_t(r.query_t_ns, r.log_clock)}" if r.query_t_ns is not None else f"cycle {r.cycle}"
    )
    command = r.decision.command
    doc.title([f"{r.robot} at {when}: ", Seg(command or "no action logged", "bold yellow")])
    doc.fields(_decision_rows(r, lookback_s))
    _factors(doc, r)
    _alternatives(doc, r)
    _counterfactuals(doc, r)
    if r.decision.tree is not None:
        doc.heading("Counterfactual tree (=> taken path)")
        doc.tree(tree_item(r))
        for problem in r.decision.tree.problems:
            doc.line(Seg(f"! {problem}", "red"), 2)
    doc.heading("Causal chains (sensor evidence -> action)")
    if not r.chains.factors:
        doc.line(Seg(f"no chain: {r.chains.reason}", "red"), 2)
    for chain in r.chains.factors:
        doc.tree(chain_item(r, chain))
    if r.external_evidence:
        external_evidence(doc, r)
    sensors(doc, r)
    _execution(doc, r)
    _scores(doc, r)
    _integrity(doc, r)
    return doc


# --- what was decided, when ---------------------------------------------------------------------


def _decision_rows(r: Explanation, lookback_s: float) -> list[tuple[str, Line]]:
    """Where the decision was read, when it was made against the asked time, its action,
    since when it held, and its rationale."""
    d = r.decision
    where = f"{r.path}"
    if r.recovered:
        where += " (recovered from an unfinished segment)"
    elif r.live:
        where += " (live: the log is being written)"
    rows: list[tuple[str, Line]] = [("Log", where), ("Decision", _decided(r))]
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
        rows.append(("Clock", _clock_line(r)))
    if d.summary:
        rows.append(("Tier", "warm summary: only what the summary kept is shown"))
    action = d.command or "?"
    extras = [f"{k}={fmt_value(v)}" for k, v in d.parameters.items()]
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
    return rows


def _decided(r: Explanation) -> str:
    if r.query_t_ns is None:
        return f"cycle {r.cycle} at {fmt_t(r.t_ns, r.log_clock)}"
    if r.offset_ns == 0:
        return f"cycle {r.cycle}, decided exactly at the asked time"
    before = f"{fmt_duration(r.offset_ns)} before the asked time"
    return f"cycle {r.cycle} at {fmt_t(r.t_ns, r.log_clock)}, {before}"


def _clock_line(r: Explanation) -> Seg:
    """Which run of the robot's clock (it went back: a declared step or a restart) the
    decision was read in."""
    run = r.clock_run[0] if len(r.clock_run) == 1 else f"{r.clock_run[0]}..{r.clock_run[-1]}"
    return Seg(
        f"the robot's clock went back in this log (see timeline): read in the run of {run}"
        + (
            "; another run may hold a decision at the same time (ask by --cycle)"
            if r.query_t_ns is not None
            else ""
        ),
        "yellow",
        None,
    )


def _held_line(r: Explanation, lookback_s: float) -> str:
    h = r.held
    span = fmt_duration(r.t_ns - h.since_t_ns)
    if h.cycles <= 1 and h.bound == "change":
        return f"new at this cycle (before: {h.previous or '?'}, cycle {h.previous_cycle})"
    since = fmt_t(h.since_t_ns, r.log_clock)
    base = f"since {since} (cycle {h.since_cycle}; {span}, {h.cycles} cycles)"
    if h.bound == "change":
        return f"{base}; before it: {h.previous or '?'} (cycle {h.previous_cycle})"
    if h.bound == "lookback":
        return (
            f"at least {base}; stopped looking after {fmt_duration(int(lookback_s * 1e9))}"
            " (--lookback)"
        )
    return f"at least {base}: the log starts there"


# --- on what, against what ----------------------------------------------------------------------


def _factors(doc: Doc, r: Explanation) -> None:
    doc.heading("Factors")
    factors = r.decision.factors
    if factors:
        doc.table(
            [Column("factor"), Column("value", "right"), Column("belief node", wrap=True)],
            [[_factor_name(f, i == 0), f.shown, f.node] for i, f in enumerate(factors)],
        )
    else:
        doc.line(Seg("none logged: the decision cannot be traced to evidence", "red"), 2)


def _factor_name(f: FactorValue, leading: bool) -> Line:
    return [f.label, Seg(" (leading)", "dim")] if leading else f.label


def _alternatives(doc: Doc, r: Explanation) -> None:
    doc.heading("Alternatives (why each lost)")
    alternatives = r.decision.alternatives
    if alternatives:
        doc.table(
            [Column("command"), Column("score", "right"), Column("rejected because", wrap=True)],
            [
                [a.command, "-" if a.score is None else f"{a.score:.2f}", a.rejected_because]
                for a in alternatives
            ],
        )
    else:
        doc.line(Seg("none logged", "red"), 2)


def _counterfactuals(doc: Doc, r: Explanation) -> None:
    d = r.decision
    doc.heading("Counterfactuals")
    if d.counterfactuals:
        for cf in d.counterfactuals:
            now = f"  (now {fmt_value(cf.value, cf.unit)})" if cf.value is not None else ""
            doc.line([Seg(cf.text, "bold"), now], 2)
    elif d.counterfactuals_none_applicable:
        doc.line("none applicable (declared by the policy)", 2)
    else:
        doc.line(Seg("none logged", "red"), 2)


# --- executed how -------------------------------------------------------------------------------


def _execution(doc: Doc, r: Explanation) -> None:
    """Intended against actual, per channel and as planar motion, with checks and flags."""
    doc.heading("Execution")
    ex = r.decision.execution
    if ex is None:
        doc.line(Seg("not logged", "red"), 2)
        return
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
                    fmt_value(c.intended),
                    fmt_value(c.actual),
                    fmt_value(c.deviation),
                    c.unit,
                ]
                for c in ex.channels
            ],
        )
    motion: list[tuple[str, Line]] = (
        [("Intended", _motion(ex.intended)), ("Actual", _motion(ex.actual))]
        if ex.planar or not ex.channels
        else []
    )
    deviation = fmt_value(ex.deviation)
    if ex.deviation_unit and ex.deviation is not None:
        deviation += f" {ex.deviation_unit}"
    checks = "; ".join(
        f"{c.rule} {'passed' if c.passed else 'FAILED'}"
        + (
            f" ({fmt_value(c.value)} vs limit {fmt_value(c.limit)})"
            if c.value is not None and c.limit is not None
            else ""
        )
        for c in ex.checks
    )
    doc.fields(
        [
            *motion,
            ("Deviation", deviation),
            ("Checks", checks or "none logged"),
            ("Flags", Seg(", ".join(ex.problems), "bold red") if ex.problems else "none"),
            *([("Scenario", ex.scenario)] if ex.scenario else []),
        ]
    )
    channel_evidence(doc, r)


def _motion(m: tuple[float | None, float | None]) -> str:
    lin, ang = m
    return f"{fmt_value(lin)} m/s, {fmt_value(ang)} rad/s"


# --- scored and sealed how ----------------------------------------------------------------------


def _scores(doc: Doc, r: Explanation) -> None:
    doc.heading("Auditability of this decision")
    s = r.scores
    traceable = sum(1 for c in r.chains.factors if c.traceable)
    unread = sum(1 for c in r.chains.factors if c.unknown)
    score_rows: list[tuple[str, Line]] = [
        (
            "ET",
            f"{_score(s.et)}  ({traceable} of {len(r.chains.factors)} factors traced to "
            "a sensor reading"
            + (f"; {unread} unknown: in a recording that could not be read)" if unread else ")"),
        ),
        ("ET_partial", _score(s.et_partial)),
        ("DR", f"{s.dr:.0f}"),
        ("TCS", _score(s.tcs)),
    ]
    doc.fields(score_rows)
    for problem in s.problems:
        doc.line(Seg(f"- {problem}", "yellow"), 2)


def _score(value: float | None) -> str:
    """A score to two places; "?" when unknown (evidence in a recording not read)."""
    return "?" if value is None else f"{value:.2f}"


def _integrity(doc: Doc, r: Explanation) -> None:
    """The decision's seal: verified, unsealed (a crash), or failed, and what it covers."""
    doc.heading("Integrity")
    seal = r.seal
    rows: list[tuple[str, Line]] = [("Seal", [_seal_status(r), f" ({seal.state})"])]
    if seal.sealed:
        rows += _sealed_rows(r)
    doc.fields(rows)
    for problem in seal.problems:
        doc.line(Seg(f"- {problem}", "yellow" if seal.in_flight else "red"), 2)


def _seal_status(r: Explanation) -> Seg:
    seal = r.seal
    if seal.verified:
        return Seg("✔ seal verifies", "bold green", "[ok] seal verifies")
    if seal.in_flight:
        # The normal end of a crashed segment (PROFILE §8): unverifiable, not a failed check.
        return Seg("⚠ UNSEALED", "bold yellow", "[UNSEALED]")
    if not seal.sealed:
        return Seg("✘ not sealed", "bold red", "[FAILED] not sealed")
    return Seg("✘ seal does NOT verify", "bold red", "[FAILED] seal does not verify")


def _sealed_rows(r: Explanation) -> list[tuple[str, Line]]:
    """What a seal covers: the layers, the evidenced readings, the chain link, the drops."""
    seal = r.seal
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
    rows: list[tuple[str, Line]] = [("Layers", layers)]
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
    return rows
