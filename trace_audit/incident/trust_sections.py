"""The report's sections on whether the record can be trusted: its integrity (the one
verdict of ``verify``) and the auditability of the decision and of the window around it.

Each ``*_section`` takes the ``ReportData`` and returns the section's HTML body; every
string from the log passes through ``html.escape``.
"""

from __future__ import annotations

from collections.abc import Sequence
from html import escape

from trace_audit.incident.data import ReportData
from trace_audit.incident.markup import html_fields, html_problems, html_table
from trace_audit.log_time import LogClock
from trace_audit.rules import RobotRules
from trace_runtime.verification import Finding
from trace_runtime.verification.report import KIND_WORDS

__all__ = ["auditability_section", "integrity_section", "rules_section"]

_OUTCOMES = {
    "satisfied": '<span class="verdict pass">satisfied</span>',
    "violated": '<span class="verdict fail">VIOLATED</span>',
    "not_decidable": '<span class="verdict warn">not decidable</span>',
}


def rules_section(data: ReportData) -> str:
    """Each safety rule given, judged over the window on the decision's robot (``check``):
    its outcome and robustness, and each violation with the decision in force."""
    judged = data.rules
    assert judged is not None  # the page holds this section only when rules were given
    clock = data.explanation.log_clock
    source = escape(data.rules_path or "the rules given")
    return (
        f"<p>The rules of {source}, judged over the window ({judged.cycles} cycles; a rule's "
        "robustness is how far the worst cycle is from breaking it, negative when broken; "
        "a window over a gap or the log's edge is not decidable). docs/rules.md.</p>"
        + _rule_outcomes(judged)
        + _unseen_names(judged)
        + _violations(judged, clock)
        + _not_decidable(judged, clock)
    )


def _rule_outcomes(judged: RobotRules) -> str:
    """One row per rule: its outcome, robustness, cycles judged and violations."""
    rows = []
    for rule in judged.rules:
        robustness = "" if rule.robustness is None else f"{rule.robustness:.4g}"
        rows.append(
            [
                f"<code>{escape(rule.rule)}</code><br><small>{escape(rule.stl)}</small>",
                _OUTCOMES[str(rule.outcome)],
                robustness,
                str(rule.decidable_cycles),
                str(len(rule.violations)),
            ]
        )
    return html_table(
        ["rule", "outcome", "robustness", "cycles judged", "violations"], rows, {2, 3, 4}
    )


def _unseen_names(judged: RobotRules) -> str:
    """A note for each name a rule reads that the window never shows."""
    notes = []
    for rule in judged.rules:
        outside = {seen.signal: seen for seen in rule.seen_outside}
        for name in rule.unseen:
            seen = outside.get(name)
            where = (
                " (a typo?)"
                if seen is None
                else f"; the log shows it {escape(judged.clock.show(seen.first_ns))} – "
                f"{escape(judged.clock.show(seen.last_ns))}"
            )
            notes.append(
                f'<p class="warn">Note: the window never shows <code>{escape(name)}</code>, '
                f"read by <code>{escape(rule.rule)}</code>{where}.</p>"
            )
    return "".join(notes)


def _violations(judged: RobotRules, clock: LogClock) -> str:
    """Each violation: when, which cycles, how badly, the decision in force."""
    violations = [
        [
            f"<code>{escape(rule.rule)}</code>",
            f"{escape(clock.show(v.start_ns))} – {escape(clock.show(v.end_ns))}",
            f"{v.first_cycle}–{v.last_cycle}",
            f"{v.robustness:.4g}",
            escape(v.command or "none"),
            f"<code>{escape(v.explain)}</code>",
        ]
        for rule in judged.rules
        for v in rule.violations
    ]
    if not violations:
        return "<p>No rule is violated in the window.</p>"
    return html_table(
        ["rule", "when", "cycles", "robustness", "decision", "explain"], violations, {3}
    )


def _not_decidable(judged: RobotRules, clock: LogClock) -> str:
    """The stretches no rule could be decided on, the first ``_LISTED`` of them."""
    undecided = [
        [
            f"<code>{escape(rule.rule)}</code>",
            f"{escape(clock.show(u.start_ns))} – {escape(clock.show(u.end_ns))}",
            f"{u.first_cycle}–{u.last_cycle}",
            escape(u.detail),
        ]
        for rule in judged.rules
        for u in rule.undecided
    ]
    if not undecided:
        return ""
    more = (
        f"<p>… and {len(undecided) - _LISTED} more (<code>check --json</code> lists them all).</p>"
        if len(undecided) > _LISTED
        else ""
    )
    return (
        "<h3>Not decidable</h3>"
        + html_table(["rule", "when", "cycles", "why"], undecided[:_LISTED], set())
        + more
    )


_LISTED = 20
"""Not-decidable stretches shown on the page; the rest are counted."""


def integrity_section(data: ReportData) -> str:
    seal, report, verdict = data.explanation.seal, data.integrity, data.verdict
    if seal.verified:
        decision = '<span class="verdict pass">seal verifies</span>'
    elif seal.in_flight:  # the normal end of a crashed segment (PROFILE §8), not a failure
        decision = (
            '<span class="verdict warn">UNSEALED</span> the robot stopped while writing this '
            "cycle; its content cannot be verified"
        )
    else:
        decision = '<span class="verdict fail">seal does NOT verify</span>'
    if not report.ok:
        window_verdict = f'<span class="verdict fail">{len(report.findings)} FINDING(S)</span>'
    elif verdict.anchored or seal.in_flight:
        # the segments are clean; whether this decision is anchored is the Anchored row's
        window_verdict = '<span class="verdict pass">CLEAN</span>'
    else:  # chained, but nothing signed or checkpointed vouches for this decision yet
        window_verdict = '<span class="verdict warn">CLEAN, NOT ANCHORED</span>'

    if data.key_id is not None:
        signatures = (
            f"checked against key {escape(data.key_id)}: "
            f"{report.checkpoints_valid} of {report.checkpoints} checkpoints valid"
        )
    else:
        signatures = (
            f"not checked (no --key given); {report.checkpoints} checkpoints, "
            f"{report.checkpoints_valid} match the chain"
        )
    link = "matches" if seal.prev_ok else "does NOT match"
    if seal.sealed:
        chain = f"prev {link} {seal.prev_source}"
    elif seal.in_flight:
        chain = "not chained: the robot stopped before sealing it" + (
            f"; the chain ends at the seal of cycle {seal.prev_cycle}"
            if seal.prev_cycle is not None
            else ""
        )
    else:
        chain = "not sealed"
    rows = [
        ("This decision", f"{decision} ({escape(seal.state)})"),
        ("Hash chain", escape(chain)),
        ("Anchored", escape(_anchoring(data))),
        (
            "Segments holding the window",
            f"{window_verdict} {escape(', '.join(data.integrity_scope))}: "
            f"{report.cycles_valid} of {report.cycles} cycles verify",
        ),
        ("Signatures", signatures),
        ("Declared drops", str(report.declared_dropped)),
    ]
    # The cycle in flight's one "problem" is the verdict row itself, not a failure to list.
    problems = [] if seal.in_flight else list(seal.problems)
    return (
        html_fields(rows)
        + html_problems(problems)
        + _findings(report.findings)
        + _notes(report.notes)
    )


def _findings(findings: Sequence[Finding]) -> str:
    """verify's findings in words, each with its kind as a data attribute (for scripts)."""
    listed = "".join(
        f'<li data-kind="{escape(f.kind)}">{escape(_said(f.kind))}: {escape(f.message)}</li>'
        for f in findings
    )
    return f'<ul class="problems">{listed}</ul>' if listed else ""


def _said(kind: str) -> str:
    """A finding or note kind as a reader of the page says it."""
    words = KIND_WORDS.get(kind, kind.replace("_", " "))
    return words[:1].upper() + words[1:]


def _anchoring(data: ReportData) -> str:
    """Whether a checkpoint in the segments holding the window vouches for this decision."""
    verdict = data.verdict
    through = verdict.anchored_through
    if verdict.anchored:
        return f"yes: a checkpoint vouches for the chain through cycle {through}"
    covered = "no checkpoint" if through is None else f"checkpoints reach only cycle {through}"
    if not data.explanation.seal.sealed:
        return (
            f"no: an unsealed cycle is not in the chain, so no checkpoint can vouch for it "
            f"({covered} in the segments holding the window)"
        )
    return (
        f"not yet: {covered} in the segments holding the window; this decision is chained, "
        "but nothing vouches for it there (the robot crashed, or the log is cut); a later "
        "segment's checkpoint may: run trace-audit verify on the whole log"
    )


def _notes(notes: Sequence[Finding]) -> str:
    """verify's notes (not tampering), one line per kind: the first message and a count."""
    by_kind: dict[str, list[Finding]] = {}
    for note in notes:
        by_kind.setdefault(note.kind, []).append(note)
    lines = []
    for kind, items in by_kind.items():
        more = f" (and {len(items) - 1} more like it)" if len(items) > 1 else ""
        lines.append(
            f'<p class="note" data-kind="{escape(kind)}">{escape(_said(kind))}: '
            f"{escape(items[0].message)}{more}</p>"
        )
    return "".join(lines)


def auditability_section(data: ReportData) -> str:
    s = data.explanation.scores
    chains = data.explanation.chains
    traced = sum(1 for c in chains.factors if c.traceable)
    # ET is unknown (not 0) while a chain stops at a recording that could not be read
    unknown = chains.unknown
    not_read = sum(1 for c in chains.factors if c.unknown)
    decision = html_fields(
        [
            (
                "ET",
                f"? ({traced} of {len(chains.factors)} factors traced to a sensor reading, "
                f"{not_read} unknown: evidence in a recording that could not be read)"
                if unknown or s.et is None
                else f"{s.et:.2f} ({traced} of {len(chains.factors)} factors "
                "traced to a sensor reading)",
            ),
            ("ET_partial", "?" if s.et_partial is None else f"{s.et_partial:.2f}"),
            ("DR", f"{s.dr:.0f}"),
            ("TCS", "?" if s.tcs is None else f"{s.tcs:.2f}"),
        ]
    )
    return (
        "<h3>This decision</h3>"
        + decision
        + html_problems(s.problems)
        + "<h3>The window</h3>"
        + _window_fields(data)
        + _gaps_table(data)
        + f'<p class="note">{escape(s.source)}.</p>'
    )


def _window_fields(data: ReportData) -> str:
    """The window's continuity, drops and mean scores ("?" where nothing is known)."""
    m = data.metrics.overall
    tc = "n/a" if m.tc is None else f"{m.tc:.3f}"
    return html_fields(
        [
            ("TC", f"{tc} ({m.gaps} gaps, {m.gap_s:.2f} s of {m.window_s:.2f} s)"),
            ("Declared drops", f"{m.declared_dropped} cycles the logger said it could not write"),
            (
                "Decisions",
                f"{m.decisions} ({m.fully_traceable} fully traceable, "
                f"{m.not_reconstructable} not reconstructable"
                + (
                    f", {m.unknown} unknown: evidence in a recording not read)"
                    if m.unknown
                    else ")"
                ),
            ),
            (
                "ET (mean)",
                "? (no decision's ET is known)"
                if m.et.mean is None or m.et.std is None
                else f"{m.et.mean:.3f} ± {m.et.std:.3f} (std {escape(m.et.across)})",
            ),
            ("DR", "n/a" if m.dr is None else f"{m.dr:.3f}"),
            ("TCS (mean)", "?" if m.tcs.mean is None else f"{m.tcs.mean:.3f}"),
        ]
    )


def _gaps_table(data: ReportData) -> str:
    """The window's gaps, one row each ('' when there is none)."""
    return (
        html_table(
            ["after cycle", "before cycle", "missing time", "declared dropped"],
            (
                [
                    str(g.after_cycle),
                    str(g.before_cycle),
                    f"{g.gap_ns / 1e9:.3f} s",
                    "?" if g.declared_dropped is None else str(g.declared_dropped),
                ]
                for g in data.metrics.gaps
            ),
            {2, 3},
        )
        if data.metrics.gaps
        else ""
    )
