"""The incident report: one self-contained HTML page about one decision, to hand over.

``build_report(log, t=...)`` gathers the decision (``explain``), the commands and factors
over a window around it (``timeline``), the window's auditability (``compute_metrics``) and
integrity (``verify``), and renders them with inline SVG figures (matplotlib, networkx) into
a page that loads nothing from anywhere::

    from trace_audit.incident import build_report

    report = build_report("run.mcap", t="20.0", window_s=30)
    Path("incident.html").write_text(report.html, encoding="utf-8")

matplotlib is the ``report`` extra; it is imported only when a figure is drawn.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from trace_audit.incident.data import (
    DEFAULT_WINDOW_S,
    ReportData,
    Verdict,
    gather_report,
    parse_window,
)
from trace_audit.incident.window import execution_channels
from trace_audit.log_time import TimeArg
from trace_runtime.boundary import write_atomic
from trace_runtime.errors import UsageError

if TYPE_CHECKING:
    from trace_audit.rules import Rule
from trace_runtime.tlog.keys import PublicKey

__all__ = [
    "DEFAULT_WINDOW_S",
    "IncidentReport",
    "ReportData",
    "Verdict",
    "build_report",
    "execution_channels",
    "gather_report",
    "parse_window",
    "write_report",
]


@dataclass(frozen=True, slots=True)
class IncidentReport:
    """The rendered page and the data it shows."""

    data: ReportData
    html: str

    @property
    def size_bytes(self) -> int:
        return len(self.html.encode("utf-8"))


def build_report(
    path: str | Path,
    *,
    t: TimeArg = None,
    cycle: int | None = None,
    window_s: float = DEFAULT_WINDOW_S,
    key: PublicKey | None = None,
    evidence: Sequence[str | Path] = (),
    command_name: str = "trace-audit",
    robots: Sequence[str] = (),
    key_path: str | Path | None = None,
    rules: Sequence[Rule] = (),
    rules_path: str | Path | None = None,
) -> IncidentReport:
    """The incident report of the decision in force at ``t`` (or cycle ``cycle``) of one
    robot (``robots`` as ``explain`` takes them); ``key_path``: where ``key`` came from;
    ``rules`` (read from ``rules_path``): safety rules judged over the window."""
    try:
        import matplotlib  # noqa: F401 - the report extra
    except ImportError as err:
        raise UsageError("the report needs matplotlib: pip install 'trace-audit[report]'") from err
    from trace_audit.incident.page import render_page

    data = gather_report(
        path,
        t=t,
        cycle=cycle,
        window_s=window_s,
        key=key,
        evidence=evidence,
        robots=robots,
        key_path=key_path,
        rules=rules,
        rules_path=rules_path,
    )
    return IncidentReport(data, render_page(data, command_name=command_name))


def write_report(report: IncidentReport, out: str | Path) -> Path:
    """Write the page to ``out`` (a new file, or a regular file it replaces: re-running a
    report refreshes its page) through a fresh sibling under a name no one holds, renamed
    over whole, so a reader never sees half a report and a link planted at ``out`` or
    beside it is never followed. ``UsageError`` for a directory; ``UnsafePathError`` for a
    link or FIFO at ``out``; ``StorageError`` when it cannot be written."""
    target = Path(out)
    if target.is_dir() or not target.name or target.name in (".", ".."):
        raise UsageError(f"--out names a directory ({target}): give the report's file name")
    write_atomic(target, report.html.encode("utf-8"))
    return target
