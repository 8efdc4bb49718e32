"""``trace-audit report``: the incident report of one decision as a self-contained HTML page."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal, TypedDict

import typer

from trace_audit.cli.app import app, guarded, help_text
from trace_audit.cli.doc import Doc, Seg
from trace_audit.cli.options import (
    EvidenceOption,
    JsonOption,
    LogArgument,
    PlainOption,
    RobotsOption,
    TimeOption,
    cycle_option,
    key_option,
)
from trace_audit.cli.output import emit

if TYPE_CHECKING:
    from rich.status import Status

    from trace_audit.incident import IncidentReport

_REPORT_HELP = """Write the incident report of the decision in force at a time: one HTML
file to read, print, archive and hand over.

The page shows the decision and its one-sentence reason, the integrity of the record
(seal, hash chain, checkpoints, signatures with --key), the leading factors over a window
around t with the decision thresholds and the commands as coloured bands, the scene the
robot perceived with the evidence behind each entity, the causal chain as a graph (broken
links marked with their reason), the alternatives, counterfactuals and decision tree, the
execution (intended vs actual), the auditability scores of the decision and of the window,
with --rules the safety rules judged over the window (as check: outcome, robustness, each
violation and its explain command), and the commands that regenerate each section.
Numbers are those of explain, timeline, metrics, verify and check; the page loads nothing
from the network (figures are inline SVG).

The window runs from 2/3 of --window before t to 1/3 after it, within the log. Integrity
findings are shown in the report and do not change the exit code (use verify for that).

[bold]Examples[/bold]:

  trace-audit report run.mcap --t 20.0

  trace-audit report logs/ --t +600 --window 60s --key keys/robot.pub

  trace-audit report run.mcap --cycle 200 --json

  trace-audit report logs/ --t 21.3 --rules docs/rules/warehouse.toml
"""


@app.command("report", help=help_text(_REPORT_HELP))
def report_command(  # noqa: PLR0917 - typer maps each parameter to an option
    log: LogArgument,
    t: TimeOption = None,
    cycle: Annotated[int | None, cycle_option("Report on")] = None,
    robot: RobotsOption = None,
    window: Annotated[
        str,
        typer.Option(
            "--window", help="Length of the window shown: seconds (30, 30s) or minutes (2m)."
        ),
    ] = "30s",
    out: Annotated[Path, typer.Option("--out", help="The HTML file to write.")] = Path(
        "incident.html"
    ),
    key: Annotated[
        Path | None, key_option("The robot's Ed25519 public key, to check checkpoint signatures.")
    ] = None,
    evidence: EvidenceOption = None,
    rules: Annotated[
        Path | None,
        typer.Option(
            "--rules",
            help="Safety rules (TOML, as check takes them) to judge over the window.",
            show_default=False,
        ),
    ] = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_audit.incident import build_report, parse_window, write_report
    from trace_runtime.tlog.keys import load_public_key

    def run() -> tuple[IncidentReport, Path]:
        public = load_public_key(key) if key is not None else None
        if rules is not None:
            from trace_audit.rules import read_rules

            rulebook = read_rules(rules)  # before the log: a bad rule is exit 2 without a read
        else:
            rulebook = ()
        report = build_report(
            log,
            t=t,
            cycle=cycle,
            window_s=parse_window(window),
            key=public,
            evidence=evidence or (),
            robots=robot or (),
            key_path=key,
            rules=rulebook,
            rules_path=rules,
        )
        return report, write_report(report, out)

    if json_out or plain or not sys.stderr.isatty():
        report, written = guarded(run)
    else:
        with _status():
            report, written = guarded(run)
    emit(_summary(report, written), _summary_doc, json_out=json_out, plain=plain)


def _status() -> Status:
    from rich.console import Console

    return Console(stderr=True).status("gathering and drawing the incident report ...")


class _RuleSummary(TypedDict):
    """A rule judged over the window, in the summary."""

    rule: str
    outcome: str
    robustness: float | None
    violations: int


class _Summary(TypedDict):
    """What ``report`` prints once the page is written (``--json``: these keys, in order)."""

    out: str
    size_bytes: int
    robot: str
    cycle: int
    t_ns: int
    command: str | None
    clock: str
    log_start_ns: int
    window_start_ns: int
    window_end_ns: int
    cycles_in_window: int
    integrity: Literal["clean", "not_anchored", "unsealed", "failed"]
    integrity_ok: bool
    integrity_findings: int
    decision_verified: bool
    anchored: bool
    anchored_through: int | None
    unanchored_cycles: list[int] | None
    sections: list[str]
    rules: list[_RuleSummary] | None


def _summary(report: IncidentReport, written: Path) -> _Summary:
    from trace_audit.incident.page import sections_of

    data = report.data
    e = data.explanation
    verdict = data.verdict
    return {
        "out": str(written.resolve()),
        "size_bytes": report.size_bytes,
        "robot": e.robot,
        "cycle": e.cycle,
        "t_ns": e.t_ns,
        "command": e.decision.command,
        "clock": e.clock,
        "log_start_ns": e.log_start_ns,
        "window_start_ns": data.start_ns,
        "window_end_ns": data.end_ns,
        "cycles_in_window": len(data.samples),
        # One verdict for the page, this summary and the terminal line (ReportData.verdict)
        "integrity": verdict.kind,
        "integrity_ok": verdict.ok,
        "integrity_findings": verdict.findings,
        "decision_verified": verdict.decision_verified,
        "anchored": verdict.anchored,
        "anchored_through": verdict.anchored_through,
        "unanchored_cycles": list(verdict.unanchored) if verdict.unanchored else None,
        "sections": sections_of(data),
        "rules": None
        if data.rules is None
        else [
            {
                "rule": r.rule,
                "outcome": str(r.outcome),
                "robustness": r.robustness,
                "violations": len(r.violations),
            }
            for r in data.rules.rules
        ],
    }


def _summary_doc(summary: _Summary) -> Doc:
    from trace_audit.log_time import LogClock

    clock = LogClock(summary["clock"], summary["log_start_ns"])
    doc = Doc()
    doc.title(["Incident report: ", Seg(summary["out"], "bold")])
    integrity = _integrity_line(summary)
    doc.fields(
        [
            (
                "Decision",
                f"{summary['robot']} {summary['command']} at "
                f"{clock.show(summary['t_ns'])} (cycle {summary['cycle']})",
            ),
            (
                "Window",
                f"{clock.show(summary['window_start_ns'])} to "
                f"{clock.show(summary['window_end_ns'])}, "
                f"{summary['cycles_in_window']} cycles",
            ),
            ("Integrity", integrity),
            *([("Rules", _rules_line(summary["rules"]))] if summary["rules"] is not None else []),
            ("Size", f"{summary['size_bytes'] / 1024:.0f} KiB"),
        ]
    )
    return doc


def _rules_line(rules: list[_RuleSummary]) -> Seg:
    broken = [r["rule"] for r in rules if r["outcome"] == "violated"]
    if broken:
        return Seg(f"VIOLATED in the window: {', '.join(broken)}", "bold red")
    undecided = sum(r["outcome"] == "not_decidable" for r in rules)
    text = f"{len(rules) - undecided} of {len(rules)} satisfied"
    return Seg(text + (f", {undecided} not decidable" if undecided else ""), "green")


def _integrity_line(summary: _Summary) -> Seg:
    """The page's integrity verdict in one line: the same four cases as its badges."""
    kind = summary["integrity"]
    unanchored = summary["unanchored_cycles"]
    if kind == "failed":
        findings = summary["integrity_findings"]
        why = f"{findings} finding{'s' if findings != 1 else ''}"
        if not summary["decision_verified"]:
            why += ", this decision's seal does not verify"
        return Seg(f"NOT clean ({why}; see the report)", "bold red")
    if kind == "unsealed":
        return Seg(
            "UNSEALED: the robot stopped while writing this cycle; its content cannot be verified",
            "bold yellow",
        )
    if kind == "not_anchored":
        span = f" (cycles {unanchored[0]}..{unanchored[1]})" if unanchored else ""
        return Seg(f"clean, NOT ANCHORED{span}", "bold yellow")
    return Seg("clean", "green")
