"""What a compaction run reports: the options it ran with, progress while it runs, and per
segment, leftover and retired file what happened (or, in a dry run, would happen)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from trace_runtime.tier_formats.cold import DEFAULT_BLOCK_CYCLES, DEFAULT_LEVEL

Status = Literal["compacted", "planned", "failed", "skipped"]


@dataclass(frozen=True, slots=True)
class ColdOptions:
    """How cold segments are encoded."""

    block_cycles: int = DEFAULT_BLOCK_CYCLES
    """Cycles per block; a seek decodes one block."""
    level: int = DEFAULT_LEVEL
    """zstd level of each block."""
    jobs: int = 1
    """Worker processes, each compacting whole segments (read from disk by the worker);
    1, or a root with one segment to move, compacts in the calling process."""


@dataclass(frozen=True, slots=True)
class Progress:
    """Reported while compacting: cycles done out of all cycles this run will compact."""

    segment: str
    cycles_done: int
    cycles_total: int


ProgressCallback = Callable[[Progress], None]


@dataclass(slots=True)
class SegmentResult:
    """What happened (or, in a dry run, would happen) to one segment."""

    source: str
    target: str | None
    robot: str
    segment: int
    source_tier: str
    cycles: int
    bytes_before: int
    bytes_after: int | None
    status: Status
    detail: str = ""
    seconds: float = 0.0
    full_cycles: int | None = None
    """Warm only: cycles kept in full (the rest are summaries)."""


@dataclass(slots=True)
class Leftover:
    """Something a killed run left behind, and what this run did about it."""

    path: str
    action: str


@dataclass(slots=True)
class RetentionResult:
    path: str
    end_ns: int
    status: Literal["deleted", "would delete", "kept"]
    """``kept``: held as evidence (``detail`` says why: findings, unreadable, two copies)."""
    detail: str = ""


@dataclass(slots=True)
class CompactionReport:
    """The result of ``compact``: per-segment results, leftovers handled, retention."""

    root: Path
    tier: str
    sources: tuple[str, ...]
    dry_run: bool
    reference_ns: int | None
    reference: Literal["newest log time", "wall clock", "given"]
    older_than_ns: int
    cutoff_ns: int | None
    retention_ns: int | None
    segments: list[SegmentResult] = field(default_factory=list)
    leftovers: list[Leftover] = field(default_factory=list)
    retention: list[RetentionResult] = field(default_factory=list)
    skipped: list[SegmentResult] = field(default_factory=list)
    seconds: float = 0.0
    kept_for: tuple[str, ...] = ()
    """The compliance profiles the root carries (``compliance.toml``), whose periods the
    run's ages and retention were held to."""

    @property
    def compacted(self) -> list[SegmentResult]:
        return [s for s in self.segments if s.status == "compacted"]

    @property
    def failed(self) -> list[SegmentResult]:
        return [s for s in self.segments if s.status == "failed"]

    @property
    def bytes_before(self) -> int:
        return sum(s.bytes_before for s in self.segments if s.status != "failed")

    @property
    def bytes_after(self) -> int:
        return sum(s.bytes_after or 0 for s in self.segments if s.status == "compacted")

    @property
    def cycles(self) -> int:
        return sum(s.cycles for s in self.segments if s.status != "failed")

    @property
    def held(self) -> list[Leftover]:
        """Leftovers that could not be settled safely: two copies kept for a human."""
        return [leftover for leftover in self.leftovers if leftover.action.startswith("held")]


def rel_path(root: Path, path: Path) -> str:
    """``path`` relative to the log root, with forward slashes (as reports name files)."""
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return str(path)


def file_size(path: Path) -> int:
    """The size of a file, 0 if it cannot be read."""
    try:
        return path.stat().st_size
    except OSError:
        return 0
