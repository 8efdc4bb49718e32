"""``trace-audit export``: a decision's causal graph and counterfactual tree as dot,
mermaid or JSON, on stdout or into a file.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import typer

from trace_audit.cli.app import EXIT_USAGE, app, fail, guarded, help_text
from trace_audit.cli.options import (
    EvidencePaths,
    LogArgument,
    PlainOption,
    RobotsOption,
    TimeOption,
    cycle_option,
    evidence_option,
)
from trace_audit.cli.output import print_json

__all__ = ["EXPORT_FORMATS", "export_command"]

EXPORT_FORMATS = ("dot", "mermaid", "json", "foxglove")

_EXPORT_HELP = """Export a decision's causal graph and counterfactual tree for a report.

dot (Graphviz), mermaid (Markdown-friendly) or json. Undocumented links are dashed and
labelled MISSING; the tree's taken path is bold.

--format foxglove writes a whole robot's log (or --from/--to of it) as an MCAP file for
Foxglove into --out: the robot and its perceived entities in 3-D, each decision change as a
log line, factors and actuator channels for the Plot panel, and the TRACE channels copied
through (trace-audit verify checks the export). docs/foxglove.md; needs the look extra.

[bold]Examples[/bold]:

  trace-audit export run.mcap --t 12.3 --format dot --out stop.dot

  trace-audit export run.mcap --t 12.3 --format mermaid >> incident.md

  trace-audit export run.mcap --cycle 4242 --format json

  trace-audit export logs/ --robot amr-7 --format foxglove --out view.mcap
"""


_FormatOption = Annotated[
    str, typer.Option("--format", help=f"One of {', '.join(EXPORT_FORMATS)}.")
]
_OutOption = Annotated[
    Path | None,
    typer.Option("--out", help="Write to this file instead of stdout.", show_default=False),
]
_ExportJsonOption = Annotated[
    bool,
    typer.Option(
        "--json",
        help="Print the export and its counts (cycle, nodes, edges, undocumented links) "
        "as one JSON object.",
    ),
]
_FromOption = Annotated[
    str | None,
    typer.Option(
        "--from",
        help="foxglove: start of the window (as --t). Default: the log start.",
        show_default=False,
    ),
]
_ToOption = Annotated[
    str | None,
    typer.Option(
        "--to",
        help="foxglove: end of the window (as --t). Default: the log end.",
        show_default=False,
    ),
]


# verify's words: the recordings the log declares are found without it
_EvidenceOption = Annotated[
    EvidencePaths, evidence_option(then=": their digests are checked there. Repeat for several.")
]


@app.command("export", help=help_text(_EXPORT_HELP))
def export_command(
    log: LogArgument,
    *,
    t: TimeOption = None,
    cycle: Annotated[int | None, cycle_option("Export")] = None,
    robot: RobotsOption = None,
    fmt: _FormatOption = "dot",
    out: _OutOption = None,
    json_out: _ExportJsonOption = False,
    plain: PlainOption = False,  # the export is plain text already; accepted like elsewhere
    start: _FromOption = None,
    end: _ToOption = None,
    evidence: _EvidenceOption = None,
) -> None:
    if fmt not in EXPORT_FORMATS:
        fail(f"unknown export format {fmt!r} (use {', '.join(EXPORT_FORMATS)})", EXIT_USAGE)
    if fmt == "foxglove":
        if t is not None or cycle is not None:
            given = "--t" if t is not None else "--cycle"
            fail(
                f"--format foxglove exports a window (--from/--to), not one decision: drop {given}",
                EXIT_USAGE,
            )
        _foxglove(log, out, robot or (), start, end, json_out=json_out, evidence=evidence or ())
        return
    _decision(log, t, cycle, robot or (), fmt, out, json_out=json_out, evidence=evidence or ())


def _decision(  # noqa: PLR0917 - the export command's options for one decision
    log: Path,
    t: str | None,
    cycle: int | None,
    robots: list[str] | tuple[str, ...],
    fmt: str,
    out: Path | None,
    *,
    json_out: bool,
    evidence: Sequence[Path],
) -> None:
    """One decision's export (dot, mermaid, json): on stdout, or written to a new file."""
    from trace_audit.export import export_decision
    from trace_runtime.boundary import write_new

    result = guarded(
        lambda: export_decision(
            log, t=t, cycle=cycle, fmt=fmt, robots=robots, evidence=list(evidence)
        )
    )
    if json_out and out is None:
        print_json(result)
        return
    if out is None:
        sys.stdout.write(result.text)
        return
    guarded(lambda: write_new(out, result.text.encode("utf-8")))  # never over a file
    sys.stderr.write(
        f"trace-audit: wrote {out} ({result.format}: cycle {result.cycle}, "
        f"{result.nodes} nodes, {result.edges} edges, {result.undocumented} undocumented)\n"
    )


def _foxglove(
    log: Path,
    out: Path | None,
    robots: list[str] | tuple[str, ...],
    start: str | None,
    end: str | None,
    *,
    json_out: bool,
    evidence: Sequence[Path],
) -> None:
    """``--format foxglove``: the library writes the file; this says what it wrote."""
    if out is None:
        fail("--format foxglove writes an MCAP file: give --out FILE.mcap", EXIT_USAGE)
    from trace_audit.foxglove.export import export_foxglove

    target = out
    result = guarded(
        lambda: export_foxglove(
            log, target, robots=tuple(robots), start=start, end=end, evidence=list(evidence)
        )
    )
    if json_out:
        print_json(result)
        return
    sys.stderr.write(
        f"trace-audit: wrote {result.path} (foxglove: {result.robot}, {result.cycles} cycles, "
        f"{result.scene_updates} scene updates, {result.decision_changes} decision changes)\n"
    )
