"""Compliance profiles: a log root checked against the logging duties of a law, clause by
clause (docs/compliance.md)::

    from trace_audit.comply import comply, load_profile

    report = comply("logs/", load_profile("ai-act-art12"), key=public_key)
    report.conforms, [(c.reference, c.verdict) for c in report.clauses]

``profile`` reads a profile (shipped by name, or a user's file); ``evidence`` gathers what
the checks read from the root (the verifier's report, the witness store, versions, safety
checks, the adopted profiles, the retention journal); ``checks`` judges each check; ``run``
judges each clause and adopts a profile into a root; ``page`` draws the conformity evidence
page with the incident report's machinery.
"""

from __future__ import annotations

from trace_audit.comply.checks import WHAT, CheckResult, Verdict
from trace_audit.comply.page import render_conformity_page, write_conformity_page
from trace_audit.comply.profile import (
    SHIPPED,
    CheckName,
    Clause,
    Profile,
    ProfileError,
    load_profile,
    shipped_path,
)
from trace_audit.comply.run import ClauseResult, ComplianceReport, adopt, comply, report_json

__all__ = [
    "SHIPPED",
    "WHAT",
    "CheckName",
    "CheckResult",
    "Clause",
    "ClauseResult",
    "ComplianceReport",
    "Profile",
    "ProfileError",
    "Verdict",
    "adopt",
    "comply",
    "load_profile",
    "render_conformity_page",
    "report_json",
    "shipped_path",
    "write_conformity_page",
]
