"""The incident report as one self-contained HTML page.

Built with the standard library only: every string that comes from the log (robot id,
rationale, labels, rule text, paths) passes through ``html.escape``, and the data block at
the end is JSON with ``<``, ``>`` and ``&`` written as escapes, so a hostile log cannot
close a tag or open a script. The page loads nothing: its figures are inline SVG, its style
a ``<style>`` block using the reader's own sans-serif font; it prints on A4.
"""

from __future__ import annotations

import json
import shlex
from collections.abc import Sequence
from html import escape

from trace_audit.incident.data import ReportData
from trace_audit.incident.decision_sections import (
    causal_section,
    counterfactuals_section,
    execution_section,
    factors_section,
    scene_section,
    summary_section,
)
from trace_audit.incident.markup import command_badge
from trace_audit.incident.trust_sections import (
    auditability_section,
    integrity_section,
    rules_section,
)
from trace_audit.jsonout import to_jsonable

__all__ = ["SECTIONS", "html_document", "render_page", "sections_of"]

SECTIONS = (
    ("summary", "Summary"),
    ("integrity", "Integrity of the record"),
    ("rules", "Safety rules over the window"),
    ("factors", "Factors over time"),
    ("scene", "The scene at the decision"),
    ("causal", "The causal chain"),
    ("counterfactuals", "Alternatives and counterfactuals"),
    ("execution", "Execution"),
    ("auditability", "Auditability"),
    ("reproduce", "Reproduce"),
)
"""Section ids and headings, in page order (the tests check every one is there); ``rules``
only when rules were given (``sections_of``)."""


def sections_of(data: ReportData) -> list[str]:
    """The ids of the sections ``data``'s page holds, in order."""
    return [s for s, _ in SECTIONS if s != "rules" or data.rules is not None]


_CSS = """
:root { --ink:#1d1d1f; --muted:#5f6368; --line:#d8d8d8; --bad:#c0392b; --ok:#1e7b34;
        --warn:#9a6700; }
* { box-sizing: border-box; }
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial,
       sans-serif; color: var(--ink); margin: 0; background: #f4f5f7; line-height: 1.45;
       font-size: 15px; }
main { max-width: 60rem; margin: 0 auto; background: white; padding: 2rem 2.5rem 3rem; }
h1 { font-size: 1.6rem; margin: 0 0 .2rem; }
h2 { font-size: 1.2rem; margin: 2rem 0 .6rem; padding-bottom: .25rem;
     border-bottom: 2px solid var(--line); }
h3 { font-size: 1rem; margin: 1.2rem 0 .4rem; }
p.lead { font-size: 1.15rem; margin: .6rem 0 .4rem; }
#in-short { background: #f6f8fa; border-left: 4px solid #8aa4c8; padding: .5rem .8rem;
            margin: .4rem 0 1rem; }
.muted, .note { color: var(--muted); }
.note { font-size: .9rem; }
.verdict { display: inline-block; padding: .15rem .6rem; border-radius: .3rem;
           font-weight: 700; color: white; }
.verdict.pass { background: var(--ok); } .verdict.fail { background: var(--bad); }
.verdict.warn { background: var(--warn); }
.command { display: inline-block; padding: .05rem .5rem; border-radius: .3rem;
           font-weight: 700; color: white; }
.bad { color: var(--bad); font-weight: 600; } .ok { color: var(--ok); font-weight: 600; }
.warn { color: var(--warn); font-weight: 600; }
table { border-collapse: collapse; width: 100%; margin: .4rem 0 .8rem; font-size: .92rem; }
th, td { text-align: left; padding: .3rem .5rem; border-bottom: 1px solid var(--line);
         vertical-align: top; }
th { color: var(--muted); font-weight: 600; }
table.fields th { width: 12rem; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
svg.figure { width: 100%; height: auto; display: block; margin: .4rem 0; }
figure { margin: 0; } figcaption { color: var(--muted); font-size: .88rem; }
pre { background: #f6f8fa; padding: .6rem .8rem; overflow-x: auto; font-size: .85rem;
      white-space: pre-wrap; word-break: break-all; }
ul.problems li { color: var(--bad); }
footer { margin-top: 2rem; color: var(--muted); font-size: .85rem; }
@page { size: A4; margin: 14mm 12mm; }
@media print {
  /* the command and verdict badges are white text on colour: keep the colour on paper */
  body { background: white; font-size: 10.5pt; -webkit-print-color-adjust: exact;
         print-color-adjust: exact; }
  main { max-width: none; padding: 0; }
  h2 { break-after: avoid; }
  figure, table, pre { break-inside: avoid; }
  section { break-inside: auto; }
  a { color: inherit; text-decoration: none; }
}
"""


def render_page(data: ReportData, *, command_name: str = "trace-audit") -> str:
    """The whole report as an HTML document (a string)."""
    e = data.explanation
    body = [
        _header(data),
        _section("summary", summary_section(data)),
        _section("integrity", integrity_section(data)),
        *([_section("rules", rules_section(data))] if data.rules is not None else []),
        _section("factors", factors_section(data)),
        _section("scene", scene_section(data)),
        _section("causal", causal_section(data)),
        _section("counterfactuals", counterfactuals_section(data)),
        _section("execution", execution_section(data)),
        _section("auditability", auditability_section(data)),
        _section("reproduce", _reproduce(data, command_name)),
        _data_block(data),
        "<footer>Generated by trace-audit report from the log alone; every number above is "
        "recomputed by the commands under “Reproduce”.</footer>",
    ]
    when = e.log_clock.show(e.t_ns)
    title = f"Incident report: {e.robot} {e.decision.command or 'no action'} at {when}"
    return html_document(title, body)


def html_document(title: str, body: Sequence[str]) -> str:
    """A whole self-contained page: ``body``'s parts (HTML already) under ``title``, in the
    report's style, with a policy that lets it load and run nothing (the conformity page
    of ``trace-audit comply`` is built with it too)."""
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        '<meta http-equiv="Content-Security-Policy" content="default-src \'none\'; '
        "style-src 'unsafe-inline'\">\n"
        f"<title>{escape(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n<main>\n"
        + "\n".join(body)
        + "\n</main>\n</body>\n</html>\n"
    )


def _section(section_id: str, content: str) -> str:
    heading = dict(SECTIONS)[section_id]
    return f'<section id="{section_id}">\n<h2>{escape(heading)}</h2>\n{content}\n</section>'


def _header(data: ReportData) -> str:
    e, d = data.explanation, data.decision
    reason = d.rationale or "no rationale logged"
    return (
        f'<header><p class="muted">TRACE incident report · {escape(data.path)}</p>'
        f"<h1>{escape(e.robot)}: {command_badge(d.command)} "
        f"at {escape(e.log_clock.show(e.t_ns))}</h1>"
        f'<p class="lead" id="reason">{escape(reason)}</p>'
        f'<p id="in-short">{_in_short(data)}</p></header>'
    )


def _in_short(data: ReportData) -> str:
    """The page in three sentences, for a reader who has never seen the tool."""
    e, d = data.explanation, data.decision
    leading = d.leading
    first = f"The robot {escape(e.robot)} chose {escape(d.command or 'no logged action')}"
    first += f" at {escape(e.log_clock.show(e.t_ns))}"
    first += (
        f", mainly because {escape(leading.label)} was {escape(leading.shown)}."
        if leading
        else "; it logged no factor for it."
    )
    what_ifs = [cf.text for cf in d.counterfactuals]
    second = f" It {escape(' and '.join(what_ifs))}." if what_ifs else ""
    factors = e.chains.factors
    traced = sum(1 for c in factors if c.traceable)
    third = (
        f" {traced} of {len(factors)} factors trace back to a logged sensor reading, and the "
        + (
            "record of this decision verifies (not altered)."
            if e.seal.verified
            else '<span class="warn">robot stopped while writing this decision: it was never '
            "sealed, so its record cannot be verified</span>."
            if e.seal.in_flight
            else '<span class="bad">record of this decision does NOT verify</span>.'
        )
    )
    return first + second + third


def _reproduce(data: ReportData, command_name: str) -> str:
    e = data.explanation
    log = shlex.quote(data.path)
    robot = f" --robot {shlex.quote(data.robot_option)}" if data.robot_option else ""
    # The decision by its number (a time could name another run's decision after a clock
    # restart), the window to the nanosecond, in the clock the log keeps.
    at = f"--cycle {e.cycle}{robot}"
    start, end = (shlex.quote(e.log_clock.arg(t)) for t in (data.start_ns, data.end_ns))
    key_file = shlex.quote(data.key_path) if data.key_path else "PUBLIC_KEY"
    key = f" --key {key_file}" if data.key_id else ""
    given = "".join(f" --evidence {shlex.quote(e)}" for e in data.evidence)
    # The window's figures come from its robot's segments (of its clock's run) alone.
    window = " ".join(shlex.quote(p) for p in data.window_inputs) or log
    lines = [
        (
            "Summary, factors, chains, counterfactuals, execution, this decision's scores",
            f"{command_name} explain {log} {at}{given}",
        ),
        (
            "Commands over the window",
            f"{command_name} timeline {log}{robot} --from {start} --to {end}",
        ),
        ("Integrity", f"{command_name} verify {log}{robot}{key}{given}"),
        (
            "Window auditability",
            f"{command_name} metrics {window} --start {start} --end {end} --failures{given}",
        ),
        ("Causal graph as Graphviz", f"{command_name} export {log} {at} --format dot"),
        *(
            [
                (
                    "Safety rules over the window",
                    f"{command_name} check {log}{robot} --rules "
                    f"{shlex.quote(data.rules_path or 'RULES.toml')} --from {start} --to {end}",
                )
            ]
            if data.rules is not None
            else []
        ),
        (
            "This report",
            f"{command_name} report {log} {at} --window {data.window_s:g}s{key}{given}"
            + (f" --rules {shlex.quote(data.rules_path)}" if data.rules_path else ""),
        ),
    ]
    return "".join(
        f"<h3>{escape(what)}</h3><pre>{escape(command)}</pre>" for what, command in lines
    )


def _data_block(data: ReportData) -> str:
    """``explain --json`` for the decision, embedded for machines (never executed)."""
    text = json.dumps(to_jsonable(data.explanation), ensure_ascii=False)
    safe = text.replace("&", "\\u0026").replace("<", "\\u003c").replace(">", "\\u003e")
    return f'<script type="application/json" id="explain-json">{safe}</script>'
