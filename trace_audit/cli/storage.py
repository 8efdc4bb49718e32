"""``trace-audit compact`` and ``trace-audit catalog``: storage tiers of a log root.

Each parses its arguments, calls one library function (``trace_runtime.tiers.compact``,
``refresh_catalog``) and renders the typed result: a ``Doc`` of a boxed table and its notes
for people, JSON for scripts.
"""

from __future__ import annotations

import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal, TypedDict

import typer

from trace_audit.cli.app import EXIT_FINDINGS, app, fail, guarded
from trace_audit.cli.doc import BoxColumn, BoxTable, Doc
from trace_audit.cli.options import (
    JsonOption,
    PlainOption,
    RootArgument,
    jobs_option,
    key_option,
    robot_option,
)
from trace_audit.cli.output import emit, progress_bar
from trace_runtime.errors import EXIT_UNREADABLE, UsageError

if TYPE_CHECKING:  # the library is imported inside each command: start-up stays light
    from collections.abc import Callable

    from trace_runtime.tiers import (
        Catalog,
        CompactionReport,
        Leftover,
        Progress,
        RetentionResult,
        SegmentResult,
    )

# The defaults shown in ``--help``, written out so that showing it does not import the
# compaction machinery (the reader, pydantic models, codecs). A test pins them to
# trace_runtime.tiers' DEFAULT_RETENTION_NS and ColdOptions().block_cycles.
_DEFAULT_RETENTION = "183d"
_DEFAULT_BLOCK_CYCLES = 256

_COMPACT_HELP = "\n\n".join(
    [
        "Move old segments of a log root (hot/ warm/ cold/) into the warm or cold tier.",
        (
            "[bold]warm[/bold]: flagged cycles (execution flags other than scenario:*, failed "
            "checks, command changes, gaps, documentation gaps) and --context around them "
            "stay byte for byte; routine cycles keep their seal and a pruned summary. Lossy "
            "by design. [bold]cold[/bold]: lossless columnar re-encoding (dictionary + delta "
            "coding, zstd) of hot or warm segments; every message decodes byte for byte."
        ),
        (
            "A segment moves when its newest log time is --older-than before the newest log "
            "time in the root (sim logs age in sim time), or before now with --now. Defaults: "
            "24h for warm (the hot window), 7d for cold. Each segment is written aside, "
            "fsynced, verified by decoding, renamed in, and only then is its source removed; "
            "a killed run is completed by the next one. Retention deletes cold segments older "
            "than --retention (default 183d) that verify clean (seals, checkpoints, and "
            "signatures with --key); a copy is removed only when a verified one stays, and "
            "only files compaction can prove its own; nothing else is ever deleted."
        ),
        (
            "A root that carries a compliance profile (compliance.toml, written by "
            "trace-audit comply --adopt) keeps its records as long as the profile asks: the "
            "defaults are raised to its period, and an --older-than (warm, when the profile "
            "asks for full detail) or --retention below it is refused (exit 2) unless "
            "--override-compliance is given."
        ),
        "[bold]Examples[/bold]:",
        "  trace-audit compact fleet/robot-7 --tier warm",
        "  trace-audit compact run/ --tier cold --older-than 0 --json",
        "  trace-audit compact /logs --tier cold --from hot --now --dry-run",
        "  trace-audit compact /logs --tier cold --jobs 4 --retention off",
        "  trace-audit compact /logs --tier cold --key keys/trace-ed25519.pub",
    ]
)

_CATALOG_HELP = "\n\n".join(
    [
        "List the segments of a log root across tiers, from its catalog (catalog.json).",
        (
            "The catalog is rebuilt from the segment files (only changed files are re-read); "
            "--refresh also writes it back. Per segment: robot, tier, segment number, time "
            "and cycle range, first and last seal digest, file SHA-256 and size. Files that "
            "cannot be read are listed; when no file is a readable segment, exit 3."
        ),
        "[bold]Examples[/bold]:",
        "  trace-audit catalog fleet/robot-7",
        "  trace-audit catalog run/ --refresh --json",
    ]
)


def _duration(text: str | None, name: str) -> int | None:
    if text is None:
        return None
    if text.strip().lower() in ("off", "none", "never"):
        if name != "--retention":
            raise UsageError(f"{name} needs a duration, e.g. 24h")
        return None
    from trace_runtime.tiers import parse_duration

    return parse_duration(text)


def _retention_ns(text: str | None) -> int | Literal["default"] | None:
    """``--retention``: not given is the library's default (183d, or the root's compliance
    period when longer); ``off`` is None."""
    return "default" if text is None else _duration(text, "--retention")


_Tier = Annotated[str, typer.Option("--tier", help="Target tier: warm or cold.")]
_OlderThan = Annotated[
    str | None,
    typer.Option(
        "--older-than",
        help="Age a segment must have, e.g. 24h, 7d, 0 (default 24h warm, 7d cold).",
    ),
]
_Sources = Annotated[
    list[str] | None,
    typer.Option(
        "--from",
        help="Source tier(s): hot for warm; hot and/or warm for cold (default both).",
    ),
]
_DryRun = Annotated[bool, typer.Option("--dry-run", help="Show what would move; change nothing.")]
_Now = Annotated[
    bool,
    typer.Option("--now", help="Measure age against the wall clock, not the newest log time."),
]
_Retention = Annotated[
    str | None,
    typer.Option(
        "--retention",
        help="Delete verified cold segments older than this (or 'off'); default "
        f"{_DEFAULT_RETENTION}, or the root's compliance period when longer.",
        show_default=False,
    ),
]
_OverrideCompliance = Annotated[
    bool,
    typer.Option(
        "--override-compliance",
        help="Delete or summarise records younger than the root's compliance profile keeps.",
    ),
]
_Context = Annotated[
    str, typer.Option("--context", help="Warm: time kept in full around each flagged cycle.")
]
_KeepReadings = Annotated[
    bool,
    typer.Option(
        "--keep-readings",
        help="Warm: keep the sensor readings a summary's evidence refs point at.",
    ),
]
_Informational = Annotated[
    list[str] | None,
    typer.Option(
        "--informational",
        help="Warm: execution flags starting with this do not flag a cycle "
        "(repeatable; scenario: always).",
    ),
]
_BlockCycles = Annotated[
    int,
    typer.Option("--block-cycles", min=1, help="Cold: cycles per block (a seek decodes one)."),
]
_IncludeUnfinished = Annotated[
    bool,
    typer.Option(
        "--include-unfinished",
        help="Also compact a robot's newest unfinished hot segment (a crashed robot's).",
    ),
]
_CompactKey = Annotated[
    Path | None,
    key_option(
        "The robots' Ed25519 public key: retention then also checks checkpoint "
        "signatures, and keeps what does not verify."
    ),
]


@app.command("compact", help=_COMPACT_HELP)
def compact_command(
    root: RootArgument,
    *,
    tier: _Tier,
    older_than: _OlderThan = None,
    robot: Annotated[str | None, robot_option("Only this robot's segments.")] = None,
    source: _Sources = None,
    dry_run: _DryRun = False,
    now: _Now = False,
    retention: _Retention = None,
    context: _Context = "2s",
    keep_readings: _KeepReadings = False,
    informational: _Informational = None,
    block_cycles: _BlockCycles = _DEFAULT_BLOCK_CYCLES,
    jobs: Annotated[int, jobs_option("Cold: processes encoding blocks in parallel.")] = 1,
    include_unfinished: _IncludeUnfinished = False,
    key: _CompactKey = None,
    override_compliance: _OverrideCompliance = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    def run() -> CompactionReport:
        from trace_runtime.tier_formats.warm import INFORMATIONAL_PREFIXES
        from trace_runtime.tiers import ColdOptions, WarmPolicy, compact, parse_duration
        from trace_runtime.tlog.keys import load_public_key

        public = load_public_key(key) if key is not None else None
        context_ns = parse_duration(context)
        return _with_progress(
            lambda progress: compact(
                root,
                tier,
                older_than_ns=_duration(older_than, "--older-than"),
                robot=robot,
                sources=source or None,
                dry_run=dry_run,
                wall_clock=now,
                retention_ns=_retention_ns(retention),
                include_unfinished=include_unfinished,
                warm=WarmPolicy(
                    context_ns=context_ns,
                    keep_readings=keep_readings,
                    informational_prefixes=(*INFORMATIONAL_PREFIXES, *(informational or [])),
                ),
                cold=ColdOptions(block_cycles=block_cycles, jobs=jobs),
                progress=progress,
                key=public,
                override_compliance=override_compliance,
            ),
            quiet=json_out or plain,
        )

    report = guarded(run)
    emit(report, compact_doc, json_out=json_out, plain=plain, to_json=_report_json)
    _exit_on_problems(report)


def _exit_on_problems(report: CompactionReport) -> None:
    """A line on stderr for segments that failed and copies held for a human; then exit 1."""
    if report.failed:
        names = ", ".join(s.source for s in report.failed)
        sys.stderr.write(f"trace-audit: compaction failed for {names}; sources kept\n")
    if report.held:
        names = ", ".join(leftover.path for leftover in report.held)
        sys.stderr.write(f"trace-audit: copies held for a human (both kept): {names}\n")
    if report.failed or report.held:
        raise typer.Exit(EXIT_FINDINGS)


def _with_progress(
    call: Callable[[Callable[[Progress], None] | None], CompactionReport], *, quiet: bool
) -> CompactionReport:
    """``call(progress)``: with a progress bar on stderr unless ``quiet`` or not a terminal."""
    if quiet or not sys.stderr.isatty():
        return call(None)
    with progress_bar("compacting") as bar:
        task = bar.task_ids[0]

        def progress(event: Progress) -> None:
            bar.update(
                task,
                description=f"compacting {event.segment}",
                completed=event.cycles_done,
                total=event.cycles_total,
            )

        return call(progress)


class _ReportJson(TypedDict):
    """``compact --json``: the report's figures, its properties (cycles, bytes) included."""

    root: str
    tier: str
    sources: list[str]
    dry_run: bool
    reference: Literal["newest log time", "wall clock", "given"]
    reference_ns: int | None
    older_than_ns: int
    cutoff_ns: int | None
    retention_ns: int | None
    kept_for: list[str]
    cycles: int
    bytes_before: int
    bytes_after: int
    seconds: float
    segments: list[SegmentResult]
    skipped: list[SegmentResult]
    leftovers: list[Leftover]
    retention: list[RetentionResult]


def _report_json(report: CompactionReport) -> _ReportJson:
    return {
        "root": str(report.root),
        "tier": report.tier,
        "sources": list(report.sources),
        "dry_run": report.dry_run,
        "reference": report.reference,
        "reference_ns": report.reference_ns,
        "older_than_ns": report.older_than_ns,
        "cutoff_ns": report.cutoff_ns,
        "retention_ns": report.retention_ns,
        "kept_for": list(report.kept_for),
        "cycles": report.cycles,
        "bytes_before": report.bytes_before,
        "bytes_after": report.bytes_after,
        "seconds": round(report.seconds, 3),
        "segments": report.segments,
        "skipped": report.skipped,
        "leftovers": report.leftovers,
        "retention": report.retention,
    }


def _size(n: int | None) -> str:
    if n is None:
        return "-"
    value = float(n)
    for unit in ("B", "KB", "MB", "GB"):
        if value < 1024 or unit == "GB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{n} B"


def _span(ns: int) -> str:
    for unit, size in (("d", 86_400), ("h", 3600), ("m", 60)):
        if ns and ns % (size * 10**9) == 0:
            return f"{ns // (size * 10**9)}{unit}"
    return f"{ns / 1e9:g}s"


def _when(t_ns: int | None) -> str:
    """A log time as a UTC date when it can be one; a robot's own clock (a simulator's, a
    monotonic one) starts near zero, and reads as seconds, not as a day in 1970."""
    from trace_runtime.clock import EARLIEST_WALL_NS

    if t_ns is None:
        return "-"
    if t_ns < EARLIEST_WALL_NS:
        return f"{t_ns / 1e9:.3f} s"
    return datetime.fromtimestamp(t_ns / 1e9, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def compact_doc(report: CompactionReport) -> Doc:
    """What compaction moved (or would move), a row per segment, what it left and deleted."""
    out = Doc()
    out.markup(
        f"[bold]compact[/bold] {report.root} -> {report.tier} (from {', '.join(report.sources)})"
    )
    out.markup(
        f"  segments older than {_span(report.older_than_ns)} before the {report.reference}"
        f" ({_when(report.reference_ns)})"
    )
    if report.kept_for:
        out.markup(
            f"  the root keeps its records for {', '.join(report.kept_for)} (compliance.toml)"
        )
    for leftover in report.leftovers:
        out.markup(f"  leftover {leftover.path}: {leftover.action}")
    if report.segments:
        out.box(_segment_table(report))
    out.markup(_moved_line(report))
    reasons: dict[str, int] = {}
    for s in report.skipped:
        reasons[s.detail] = reasons.get(s.detail, 0) + 1
    for reason, count in sorted(reasons.items()):
        out.markup(f"  left {count} segment(s): {reason}")
    for r in report.retention:
        detail = f" ({r.detail})" if r.detail else ""
        out.markup(f"  retention: {r.path} {r.status}{detail}")
    return out


def _segment_table(report: CompactionReport) -> BoxTable:
    names = ("segment", "from", "cycles", "before", "after", "ratio", "status")
    columns = tuple(
        BoxColumn(name, "left" if name in ("segment", "status") else "right") for name in names
    )
    rows = []
    for s in report.segments:
        ratio = f"{s.bytes_before / s.bytes_after:.1f}x" if s.bytes_after else "-"
        status = s.status + (f": {s.detail}" if s.detail else "")
        if s.full_cycles is not None:
            status += f" ({s.full_cycles} full, {s.cycles - s.full_cycles} summarised)"
        rows.append(
            (
                s.source.rsplit("/", 1)[-1],
                s.source_tier,
                str(s.cycles),
                _size(s.bytes_before),
                _size(s.bytes_after),
                ratio,
                status,
            )
        )
    return BoxTable(columns, tuple(rows))


def _moved_line(report: CompactionReport) -> str:
    """How much moved, at what ratio and speed; or what would move; or nothing."""
    verb = "would move" if report.dry_run else "moved"
    compacted = report.compacted
    if compacted:
        rate = report.cycles / report.seconds if report.seconds > 0 else 0.0
        return (
            f"  {verb} {len(compacted)} segment(s), {report.cycles} cycles: "
            f"{_size(report.bytes_before)} -> {_size(report.bytes_after)} "
            f"({report.bytes_before / max(1, report.bytes_after):.1f}x) in {report.seconds:.1f} s "
            f"({rate:,.0f} cycles/s)"
        )
    if report.dry_run and report.segments:
        return f"  {verb} {len(report.segments)} segment(s), {report.cycles} cycles"
    return "  nothing to move"


@app.command("catalog", help=_CATALOG_HELP)
def catalog_command(
    root: RootArgument,
    *,
    refresh: Annotated[
        bool, typer.Option("--refresh", help="Write the rebuilt catalog to catalog.json.")
    ] = False,
    json_out: JsonOption = False,
    plain: PlainOption = False,
) -> None:
    from trace_runtime.tiers import refresh_catalog

    catalog = guarded(lambda: refresh_catalog(root, write=refresh))
    emit(
        catalog,
        catalog_doc,
        json_out=json_out,
        plain=plain,
        to_json=lambda c: {"root": str(root), "segments": c.entries, "problems": c.problems},
    )
    if not catalog.entries and catalog.problems:
        # Files in the tiers and none of them a segment: unreadable input, not an empty root.
        fail(f"{root}: no readable segment ({catalog.problems[0]})", EXIT_UNREADABLE)


def catalog_doc(catalog: Catalog) -> Doc:
    """A row per segment of the catalog, the total, and what could not be read.

    Too wide for the console, the tier and the times wrap; the robot is never cut (at its
    full width even when the table then runs past the edge), nor are the numbers."""
    robot_width = max((len(e.robot) for e in catalog.entries), default=0)
    columns = (
        BoxColumn("robot", min_width=max(len("robot"), robot_width), no_wrap=True),
        BoxColumn("seg", "right", no_wrap=True),
        BoxColumn("tier"),
        BoxColumn("start"),
        BoxColumn("end"),
        BoxColumn("cycles", "right", no_wrap=True),
        BoxColumn("size", "right", no_wrap=True),
    )
    rows = tuple(
        (
            e.robot,
            str(e.segment),
            e.tier + ("*" if e.lossy else "") + ("" if e.finished else " (unfinished)"),
            _when(e.start_ns),
            _when(e.end_ns),
            str(e.cycles),
            _size(e.bytes),
        )
        for e in catalog.entries
    )
    out = Doc()
    out.box(BoxTable(columns, rows, title=f"catalog of {catalog.root}"))
    total = sum(e.bytes for e in catalog.entries)
    lossy = any(e.lossy for e in catalog.entries)
    out.markup(
        f"  {len(catalog.entries)} segment(s), {_size(total)}"
        + ("; * lossy (warm summaries)" if lossy else "")
        + "; seal digests and file SHA-256 in --json"
    )
    for problem in catalog.problems:
        out.markup(f"  unreadable: {problem}")
    return out
