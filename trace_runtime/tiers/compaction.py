"""Compaction of a log root into the warm or cold tier, and retention of the cold tier.

Each segment moves in one crash-safe sequence: write the new tier's file aside as
``<name>.mcap.partial``, fsync it, verify it against the source by decoding it, rename it
into ``warm/`` or ``cold/``, fsync the directory, update the catalog, and only then remove
the source. A run killed at any point is completed by the next one from whichever copy
verifies (``recover``): a ``.partial`` that is provably compaction's own is discarded (any
other file is left alone); of a segment found in two tiers, the copy that stays is one that
verifies, and the other is removed only when the one staying holds all it holds. Copies
that disagree while both verify, or that both fail, are held for a human. So a segment is
never lost, the last good copy is never removed, and a settled segment is in one tier.

Which segments move: those whose newest log time is ``older_than`` before the reference
time, which is the newest log time anywhere in the root (so a simulator's log, in sim
time, ages by its own clock) or, with ``wall_clock``, the current time. The newest hot
segment of a robot that is not finished is the one its logger may still be writing, and
is left alone unless ``include_unfinished``.

A root that carries compliance profiles (``compliance.toml``, ``keep``) keeps what they ask:
both defaults (warm's age when a profile asks for full detail, and retention) rise to their
period, and a shorter explicit request is refused (``UsageError``, exit 2) unless
``override_compliance``.

Retention deletes only cold segments (already compacted) whose newest log time is more
than ``retention_ns`` before the reference, and only if the verification ``trace-audit
verify`` runs (``trace_runtime.verification``: seals, links, checkpoints, and signatures when
``key`` is given) finds nothing in them; anything else is held as evidence. Each deletion is
recorded in ``retention.jsonl`` in the root first.

Segment files are found and opened through ``trace_runtime.reading.logset``, like every reader.
"""

from __future__ import annotations

import contextlib
import functools
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from trace_runtime.boundary import regular_file, tier_folder
from trace_runtime.errors import UsageError
from trace_runtime.reading.catalog_rows import CATALOG_NAME
from trace_runtime.reading.reader import Segment
from trace_runtime.session import TIERS
from trace_runtime.tier_formats.warm import WarmPolicy
from trace_runtime.tiers._files import (
    LOCK_NAME,
    PartialOpener,
    open_partial,
    require_root,
    root_lock,
)
from trace_runtime.tiers.durations import DAY_NS
from trace_runtime.tiers.keep import COMPLIANCE_NAME, RootKeep, read_keep, resolve_periods
from trace_runtime.tiers.plan import (
    Choice,
    cycle_estimate,
    plan_moves,
    reference_time,
    scan,
    segment_result,
    unreadable_results,
)
from trace_runtime.tiers.recover import recover
from trace_runtime.tiers.replace import compact_segment, refresh_quietly
from trace_runtime.tiers.report import (
    ColdOptions,
    CompactionReport,
    Progress,
    ProgressCallback,
    SegmentResult,
)
from trace_runtime.tiers.retention import RETENTION_LOG, apply_retention
from trace_runtime.tiers.workers import compact_in_workers, picklable
from trace_runtime.tlog.keys import PublicKey

__all__ = ["DEFAULT_OLDER_THAN_NS", "DEFAULT_RETENTION_NS", "DEFAULT_SOURCES", "compact"]

DEFAULT_OLDER_THAN_NS = {"warm": DAY_NS, "cold": 7 * DAY_NS}
DEFAULT_SOURCES = {"warm": ("hot",), "cold": ("hot", "warm")}
DEFAULT_RETENTION_NS = 183 * DAY_NS


def compact(
    root: str | Path,
    tier: str,
    *,
    older_than_ns: int | None = None,
    robot: str | None = None,
    sources: Iterable[str] | None = None,
    dry_run: bool = False,
    wall_clock: bool = False,
    now_ns: int | None = None,
    retention_ns: int | Literal["default"] | None = "default",
    include_unfinished: bool = False,
    warm: WarmPolicy | None = None,
    cold: ColdOptions | None = None,
    progress: ProgressCallback | None = None,
    key: PublicKey | None = None,
    opener: PartialOpener = open_partial,
    override_compliance: bool = False,
) -> CompactionReport:
    """Move every eligible segment of ``root`` into ``tier`` ("warm" or "cold"); see module doc.

    ``older_than_ns`` defaults to 24 h for warm and 7 days for cold; ``sources`` to hot for
    warm and hot + warm for cold. ``now_ns`` fixes the reference time (tests, replays).
    ``retention_ns=None`` turns retention off, ``"default"`` is 183 days; both defaults rise
    to what the root's compliance profiles keep, which refuse a shorter explicit request
    unless ``override_compliance`` (module doc). ``key``: the robots' public key; retention
    and the settling of leftovers then check signatures too. ``opener`` creates each partial
    file (a plug point for fault injection). A dry run changes nothing on disk.
    """
    root = Path(root)
    chosen = _check_target(root, tier, sources)
    older, retention, keep = _periods(root, tier, older_than_ns, retention_ns, override_compliance)
    warm_policy = warm or WarmPolicy()
    cold_options = cold or ColdOptions()
    if cold_options.block_cycles < 1 or cold_options.jobs < 1:
        raise UsageError("block_cycles and jobs must be at least 1")
    started = time.perf_counter()
    lock = contextlib.nullcontext() if dry_run else root_lock(root)
    with lock:
        settings = _Settings(
            tier=tier,
            sources=chosen,
            older_than_ns=older,
            robot=robot,
            dry_run=dry_run,
            wall_clock=wall_clock,
            now_ns=now_ns,
            retention_ns=retention,
            include_unfinished=include_unfinished,
            warm=warm_policy,
            cold=cold_options,
            key=key,
            opener=opener,
        )
        report = _run(root, settings, progress)
    report.kept_for = tuple(p.name for p in keep.profiles) if keep else ()
    report.seconds = time.perf_counter() - started
    return report


def _periods(
    root: Path,
    tier: str,
    older_than_ns: int | None,
    retention_ns: int | Literal["default"] | None,
    override: bool,
) -> tuple[int, int | None, RootKeep | None]:
    """(older_than_ns, retention_ns, the root's compliance profiles) of the run: checked,
    defaults filled in, and held to what the profiles keep (``keep.resolve_periods``)."""
    asked = DEFAULT_RETENTION_NS if retention_ns == "default" else retention_ns
    if (older_than_ns is not None and older_than_ns < 0) or (asked is not None and asked < 0):
        raise UsageError("durations must not be negative")
    keep = read_keep(root)
    older, retention = resolve_periods(
        root,
        keep,
        tier=tier,
        older_than_ns=older_than_ns,
        default_older_than_ns=DEFAULT_OLDER_THAN_NS[tier],
        retention_ns=asked,
        retention_default=retention_ns == "default",
        override=override,
    )
    return older, retention, keep


def _check_target(root: Path, tier: str, sources: Iterable[str] | None) -> tuple[str, ...]:
    """The source tiers to compact from, once ``root`` and ``tier`` are known to be usable."""
    require_root(root)
    # Refused before any work: a tier folder that is a link (compaction would write and
    # delete outside the root), or a side file that is not a file (a FIFO would hang it).
    for name in TIERS:
        tier_folder(root, name)
    for name in (CATALOG_NAME, RETENTION_LOG, LOCK_NAME, COMPLIANCE_NAME):
        regular_file(root / name)
    if tier not in ("warm", "cold"):
        raise UsageError(f"unknown target tier {tier!r}: use warm or cold")
    chosen = tuple(sources) if sources is not None else DEFAULT_SOURCES[tier]
    allowed = TIERS[: TIERS.index(tier)]
    bad = [s for s in chosen if s not in allowed]
    if bad or not chosen:
        what = ", ".join(bad) or "nothing"
        raise UsageError(f"cannot compact {what} into {tier}: sources are {', '.join(allowed)}")
    return chosen


@dataclass(frozen=True, slots=True)
class _Settings:
    """What one run of ``compact`` was asked to do, its arguments checked."""

    tier: str
    sources: tuple[str, ...]
    older_than_ns: int
    robot: str | None
    dry_run: bool
    wall_clock: bool
    now_ns: int | None
    retention_ns: int | None
    include_unfinished: bool
    warm: WarmPolicy
    cold: ColdOptions
    key: PublicKey | None
    opener: PartialOpener


def _run(root: Path, settings: _Settings, progress: ProgressCallback | None) -> CompactionReport:
    """Recover, plan, move, retire: one compaction of ``root``, the lock held."""
    leftovers = recover(root, dry_run=settings.dry_run, key=settings.key)
    segments, unreadable = scan(root)
    reference, label = reference_time(
        segments, now_ns=settings.now_ns, wall_clock=settings.wall_clock
    )
    cutoff = None if reference is None else reference - settings.older_than_ns
    report = CompactionReport(
        root=root,
        tier=settings.tier,
        sources=settings.sources,
        dry_run=settings.dry_run,
        reference_ns=reference,
        reference=label,
        older_than_ns=settings.older_than_ns,
        cutoff_ns=cutoff,
        retention_ns=settings.retention_ns,
        leftovers=leftovers,
    )
    report.skipped += unreadable_results(root, unreadable)
    choice = Choice(settings.sources, settings.robot, cutoff, settings.include_unfinished)
    plan, skipped = plan_moves(root, segments, choice)
    report.skipped += skipped
    report.segments += _move(root, plan, settings, _Advance(plan, progress))
    retention_ns = settings.retention_ns
    if retention_ns is not None and reference is not None:
        report.retention = apply_retention(
            root, reference - retention_ns, settings.robot, settings.dry_run, settings.key
        )
    if not settings.dry_run:
        refresh_quietly(root)
    return report


class _Advance:
    """Counts the cycles compacted so far out of the plan's, and reports each step."""

    def __init__(self, plan: list[tuple[Path, Segment]], progress: ProgressCallback | None):
        self._total = sum(cycle_estimate(s) for _, s in plan)
        self._done = 0
        self._progress = progress

    def __call__(self, cycles: int, name: str) -> None:
        self._done += cycles
        if self._progress is not None:
            self._progress(Progress(name, min(self._done, self._total), self._total))


def _move(
    root: Path,
    plan: list[tuple[Path, Segment]],
    settings: _Settings,
    advance: Callable[[int, str], None],
) -> Iterator[SegmentResult]:
    """Each planned segment's result: planned (a dry run), or compacted in worker processes
    or in this one."""
    tier = settings.tier
    if settings.dry_run:
        for path, segment in plan:
            target = root / tier / path.name
            yield segment_result(root, path, segment, target, status="planned", detail="")
    elif settings.cold.jobs > 1 and len(plan) > 1 and picklable(settings.opener):
        # Segments in parallel: each worker reads, encodes and checks a whole segment.
        jobs = compact_in_workers(
            root, plan, tier, (settings.warm, settings.cold, settings.opener), advance
        )
        for _path, result in jobs:
            yield result
    else:
        for path, segment in plan:
            yield compact_segment(
                root,
                path,
                segment,
                tier,
                warm_policy=settings.warm,
                cold_options=settings.cold,
                advance=functools.partial(_named, advance, path.name),
                opener=settings.opener,
            )


def _named(advance: Callable[[int, str], None], name: str, cycles: int) -> None:
    advance(cycles, name)
