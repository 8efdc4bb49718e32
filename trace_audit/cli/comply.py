"""``trace-audit comply``: a log root checked against a compliance profile, clause by clause.

Parses its arguments, reads the profile (``trace_audit.comply.load_profile``; a bad one is
exit 2 before the root is read), adopts it into the root with ``--adopt``, calls
``trace_audit.comply.comply`` and renders the typed result: a document for people, JSON with
``--json``, and with ``--html`` the conformity evidence page. Exit 1 when a clause is not met.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, guarded, help_text
from trace_audit.cli.doc import Doc, Seg
from trace_audit.cli.options import JsonOption, PlainOption, RootArgument, key_option
from trace_audit.cli.output import emit

if TYPE_CHECKING:  # the library is imported inside the command: start-up stays light
    from trace_audit.comply import ComplianceReport

_COMPLY_HELP = """Check a log root against the logging duties of a law: a compliance profile
maps each clause (its reference and a one-line summary) to checks over the root.

Profiles shipped: machinery-2023-1230 (Machinery Regulation (EU) 2023/1230, Annex III 1.1.9
and 1.2.1, from 20 January 2027) and ai-act-art12 (AI Act (EU) 2024/1689, Art. 12, 19(1) and
26(6)); or the path of your own profile (TOML, docs/compliance.md). The checks: versions
(every decision names its software and policy versions; each change is listed with its
time), signed (checkpoints signed, under --key), witnessed (cosigned by a witness, checked
with --witness-key), gaps (no undeclared gap), chain (verify finds nothing), retention
(the root keeps every tier as long as the clause asks) and safety_rules (every decision
records the safety rules checked on it).

--adopt writes the profile's period into the root (compliance.toml): compact and retention
then refuse to delete (or summarise, when the profile asks for full detail) anything
younger, unless --override-compliance. --html writes the conformity evidence page: each
clause, its checks, the evidence, the verdict and the command that reproduces it.

TRACE checks technical logging conditions; it does not certify, and whether a law applies
is the manufacturer's or deployer's decision (docs/compliance.md).

Exit codes: 0 every clause met, 1 a clause not met (named on stderr with its check and
fix), 2 a bad profile or usage, 3 an unreadable root.

[bold]Examples[/bold]:

  trace-audit comply logs/ --profile ai-act-art12 --key keys/amr-7.pub

  trace-audit comply logs/ --profile machinery-2023-1230 --html c.html

  trace-audit comply logs/ --profile ai-act-art12 --adopt --json

  trace-audit comply logs/ --profile my-profile.toml
"""

_Profile = Annotated[
    str,
    typer.Option(
        "--profile",
        help="A shipped profile (machinery-2023-1230, ai-act-art12) or a profile file.",
        show_default=False,
    ),
]
_WitnessKey = Annotated[
    str | None,
    typer.Option(
        "--witness-key",
        help="The witness's verifier key (witness vkey --cosignature): cosignatures checked.",
        show_default=False,
    ),
]
_Adopt = Annotated[
    bool,
    typer.Option(
        "--adopt",
        help="Write the profile's period into the root (compliance.toml), then check.",
    ),
]
_Html = Annotated[
    Path | None,
    typer.Option("--html", help="Write the conformity evidence page here.", show_default=False),
]


@app.command("comply", help=help_text(_COMPLY_HELP))
def comply_command(
    root: RootArgument,
    *,
    profile: _Profile,
    key: Annotated[
        Path | None, key_option("The robots' Ed25519 public key: signatures checked.")
    ] = None,
    witness_key: _WitnessKey = None,
    adopt: _Adopt = False,
    html: _Html = None,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    def run() -> ComplianceReport:
        from trace_audit.comply import adopt as adopt_into
        from trace_audit.comply import comply, load_profile, write_conformity_page
        from trace_runtime.tlog.keys import load_public_key

        chosen = load_profile(profile)  # before the root: a bad profile is exit 2, no read
        public = load_public_key(key) if key is not None else None
        if adopt:
            adopt_into(root, chosen)
        report = comply(
            root,
            chosen,
            key=public,
            witness_key=witness_key,
            key_path=str(key) if key is not None else None,
            profile_arg=profile,
        )
        if html is not None:
            write_conformity_page(report, html)
        return report

    from trace_audit.comply import report_json

    report = guarded(run)
    emit(report, comply_doc, json_out=json_out, plain=plain, to_json=report_json)
    for clause in report.failed:
        broken = [c for c in clause.checks if c.verdict != "met"]
        first = broken[0]
        sys.stderr.write(
            f"trace-audit: {report.profile} {clause.reference} not met: {first.check}: "
            f"{first.evidence[0] if first.evidence else ''}; fix: {first.fix}\n"
        )
    if not report.conforms:
        raise typer.Exit(EXIT_FINDINGS)


def comply_doc(report: ComplianceReport) -> Doc:
    """Each clause with its verdict; under a clause not met, each check with its evidence
    and fix; the changes of version as evidence either way."""
    out = Doc()
    verdict = (
        Seg("CONFORMS", "bold green") if report.conforms else Seg("DOES NOT CONFORM", "bold red")
    )
    out.title([f"{report.profile} ({report.title}) for {report.root}: ", verdict])
    for clause in report.clauses:
        mark = Seg("met", "green") if clause.met else Seg("NOT MET", "bold red")
        out.line([Seg(clause.reference, "bold"), "  ", mark, f"  {clause.summary}"])
        for check in clause.checks:
            met = check.verdict == "met"
            out.line([f"{check.check}: ", Seg(check.verdict, "green" if met else "bold red")], 1)
            shown = check.evidence if not met or check.check == "versions" else check.evidence[:1]
            for line in shown:
                out.line(line, 2)
            if check.fix:
                out.line(["fix: ", Seg(check.fix, "yellow")], 2)
    out.line(f"reproduce: {report.command}")
    return out
