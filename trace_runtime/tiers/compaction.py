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

Retention deletes only cold segments (already compacted) whose newest log time is more
than ``retention_ns`` before the reference, and only if the verification ``trace-audit
verify`` runs (``trace_runtime.verification``: seals, links, checkpoints, and signatures when
``key`` is given) finds nothing in them; anything else is held as evidence. Each deletion is
recorded in ``retention.jsonl`` in the root first.

Segment files are found and opened through ``trace_runtime.logset``, like every reader.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import pickle
import re
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from itertools import islice, zip_longest
from pathlib import Path
from typing import Any, BinaryIO, Literal, cast

import orjson

from trace_runtime.costs import TIMING_METADATA
from trace_runtime.cycles import RawMessage
from trace_runtime.errors import LogReadError, UsageError, VerificationError
from trace_runtime.keys import PublicKey
from trace_runtime.logset import FileProblem, Log, open_segments
from trace_runtime.reader import Segment
from trace_runtime.records import MESSAGE_MODELS, TOPIC_SEAL
from trace_runtime.segment import OutMessage, SegmentWriteError, SegmentWriter
from trace_runtime.session import TIER_METADATA, TIERS, SessionInfo
from trace_runtime.tiers._files import (
    PARTIAL_METADATA,
    PARTIAL_SUFFIX,
    PartialOpener,
    PartialStream,
    compaction_marker,
    fsync_dir,
    open_partial,
    partial_owner,
    partial_path,
    root_lock,
)
from trace_runtime.tiers.catalog import (
    file_digest,
    refresh_catalog,
    segment_files,
)
from trace_runtime.tiers.cold import (
    BLOCK_SCHEMA,
    BLOCK_TOPIC,
    CODEC,
    DEFAULT_BLOCK_CYCLES,
    DEFAULT_LEVEL,
    INDEX_SCHEMA,
    INDEX_TOPIC,
    BlockEncoder,
    ColdFormatError,
    gc_paused,
    index_entry,
    iter_blocks,
    iter_decoded,
    merge_plain,
    split_plain,
)
from trace_runtime.tiers.warm import SUMMARY_SCHEMA, SUMMARY_TOPIC, WarmPolicy, warm_cycles
from trace_runtime.verification import SegmentSummary, VerifyReport, verify

__all__ = [  # noqa: RUF022 - grouped by role
    "compact",
    "compact_segment",
    "recover",
    "verify_replacement",
    "chain_problems",
    "parse_duration",
    "ColdOptions",
    "CompactionReport",
    "Leftover",
    "Progress",
    "RetentionResult",
    "SegmentResult",
    "VerificationError",
]

SECOND_NS = 1_000_000_000
DAY_NS = 86_400 * SECOND_NS
DEFAULT_OLDER_THAN_NS = {"warm": DAY_NS, "cold": 7 * DAY_NS}
DEFAULT_SOURCES = {"warm": ("hot",), "cold": ("hot", "warm")}
DEFAULT_RETENTION_NS = 183 * DAY_NS
RETENTION_LOG = "retention.jsonl"
WARM_CHUNK_CYCLES = 256
WARM_LEVEL = 9

Tier = Literal["warm", "cold"]
Status = Literal["compacted", "planned", "failed", "skipped"]

_UNITS = {"s": 1, "m": 60, "h": 3600, "d": 86_400, "w": 7 * 86_400}
_DURATION = re.compile(r"\s*(\d+(?:\.\d+)?)\s*([smhdw]?)\s*")


def parse_duration(text: str) -> int:
    """Nanoseconds in ``90s``, ``30m``, ``24h``, ``7d``, ``2w`` or a bare number of seconds."""
    match = _DURATION.fullmatch(text)
    if match is None:
        raise UsageError(f"bad duration {text!r}: use e.g. 90s, 30m, 24h, 7d, 2w or 0")
    return round(float(match.group(1)) * _UNITS[match.group(2) or "s"] * SECOND_NS)


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


# --- the entry point -----------------------------------------------------------------------


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
    retention_ns: int | None = DEFAULT_RETENTION_NS,
    include_unfinished: bool = False,
    warm: WarmPolicy | None = None,
    cold: ColdOptions | None = None,
    progress: ProgressCallback | None = None,
    key: PublicKey | None = None,
    opener: PartialOpener = open_partial,
) -> CompactionReport:
    """Move every eligible segment of ``root`` into ``tier`` ("warm" or "cold"); see module doc.

    ``older_than_ns`` defaults to 24 h for warm and 7 days for cold; ``sources`` to hot for
    warm and hot + warm for cold. ``now_ns`` fixes the reference time (tests, replays).
    ``retention_ns=None`` turns retention off. ``key``: the robots' public key; retention and
    the settling of leftovers then check checkpoint signatures too. ``opener`` creates each
    partial file (a plug point for fault injection). A dry run changes nothing on disk.
    """
    root = Path(root)
    if not root.is_dir():
        raise LogReadError(str(root), "not a log root (no such directory)")
    if tier not in ("warm", "cold"):
        raise UsageError(f"unknown target tier {tier!r}: use warm or cold")
    chosen = tuple(sources) if sources is not None else DEFAULT_SOURCES[tier]
    allowed = TIERS[: TIERS.index(tier)]
    bad = [s for s in chosen if s not in allowed]
    if bad or not chosen:
        what = ", ".join(bad) or "nothing"
        raise UsageError(f"cannot compact {what} into {tier}: sources are {', '.join(allowed)}")
    older = DEFAULT_OLDER_THAN_NS[tier] if older_than_ns is None else older_than_ns
    if older < 0 or (retention_ns is not None and retention_ns < 0):
        raise UsageError("durations must not be negative")
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
            retention_ns=retention_ns,
            include_unfinished=include_unfinished,
            warm=warm_policy,
            cold=cold_options,
            key=key,
            opener=opener,
        )
        report = _run(root, settings, progress)
    report.seconds = time.perf_counter() - started
    return report


@dataclass(frozen=True, slots=True)
class _Settings:
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
    tier, sources, robot = settings.tier, settings.sources, settings.robot
    dry_run, now_ns, retention_ns = settings.dry_run, settings.now_ns, settings.retention_ns
    older_than_ns = settings.older_than_ns
    leftovers = recover(root, dry_run=dry_run, key=settings.key)
    segments, unreadable = _scan(root)
    held = _in_two_tiers(root)
    if now_ns is not None:
        reference: int | None = now_ns
        label: Literal["newest log time", "wall clock", "given"] = "given"
    elif settings.wall_clock:
        reference, label = time.time_ns(), "wall clock"
    else:
        reference = max((s.info.end_ns for s in segments.values()), default=None)
        label = "newest log time"
    cutoff = None if reference is None else reference - older_than_ns
    report = CompactionReport(
        root=root,
        tier=tier,
        sources=sources,
        dry_run=dry_run,
        reference_ns=reference,
        reference=label,
        older_than_ns=older_than_ns,
        cutoff_ns=cutoff,
        retention_ns=retention_ns,
        leftovers=leftovers,
    )
    for problem in unreadable:
        path, reason = problem.path, problem.reason
        report.skipped.append(
            SegmentResult(
                _rel(root, path),
                None,
                "",
                -1,
                path.parent.name,
                0,
                _size(path),
                None,
                "skipped",
                reason,
            )
        )
    live = _live_segments(segments)
    plan: list[tuple[Path, Segment]] = []
    for path, segment in sorted(segments.items(), key=lambda item: _order(item[1])):
        session = segment.session
        if session.tier not in sources or (robot is not None and session.robot_id != robot):
            continue
        why = ""
        if path.name in held:
            why = "held: the segment is in two tiers (see the leftovers)"
        elif cutoff is None or segment.info.end_ns > cutoff:
            why = "newer than the cutoff"
        elif path in live and not settings.include_unfinished:
            why = "unfinished newest hot segment: its logger may still be writing it"
        if why:
            report.skipped.append(_result(root, path, segment, None, status="skipped", detail=why))
            continue
        plan.append((path, segment))

    total = sum(_cycle_estimate(s) for _, s in plan)
    done = 0

    def advance(cycles: int, name: str) -> None:
        nonlocal done
        done += cycles
        if progress is not None:
            progress(Progress(name, min(done, total), total))

    if dry_run:
        for path, segment in plan:
            target = root / tier / path.name
            report.segments.append(
                _result(root, path, segment, target, status="planned", detail="")
            )
    elif settings.cold.jobs > 1 and len(plan) > 1 and _picklable(settings.opener):
        # Segments in parallel: each worker reads, encodes and checks a whole segment.
        for path, result in _compact_in_workers(root, plan, settings, advance):
            report.segments.append(result)
            del segments[path]
    else:
        for path, segment in plan:
            result = compact_segment(
                root,
                path,
                segment,
                tier,
                warm_policy=settings.warm,
                cold_options=settings.cold,
                advance=functools.partial(_named, advance, path.name),
                opener=settings.opener,
            )
            report.segments.append(result)
            del segments[path]
    if retention_ns is not None and reference is not None:
        report.retention = _retention(root, reference - retention_ns, robot, dry_run, settings.key)
    if not dry_run:
        _refresh(root)
    return report


def _named(advance: Callable[[int, str], None], name: str, cycles: int) -> None:
    advance(cycles, name)


def _refresh(root: Path) -> str:
    """Update the catalog; a failure (a full disk) is said, never fatal: the files are the
    truth and the next run rebuilds it."""
    try:
        refresh_catalog(root)
    except OSError as err:
        return f"catalog not updated ({err.strerror or err})"
    return ""


def _order(segment: Segment) -> tuple[str, int]:
    return segment.session.robot_id, segment.session.segment


def _scan(root: Path) -> tuple[dict[Path, Segment], list[FileProblem]]:
    segments, problems = open_segments(segment_files(root))
    return {s.path: s for s in segments}, problems


def _in_two_tiers(root: Path) -> set[str]:
    """Names of segment files present in more than one tier (held by ``recover``)."""
    seen: dict[str, int] = {}
    for path in segment_files(root):
        seen[path.name] = seen.get(path.name, 0) + 1
    return {name for name, count in seen.items() if count > 1}


def _live_segments(segments: dict[Path, Segment]) -> set[Path]:
    newest: dict[str, tuple[int, Path, Segment]] = {}
    for path, segment in segments.items():
        if segment.session.tier != "hot":
            continue
        key = segment.session.robot_id
        if key not in newest or segment.session.segment > newest[key][0]:
            newest[key] = (segment.session.segment, path, segment)
    return {path for _, path, segment in newest.values() if not segment.info.finished}


def _cycle_estimate(segment: Segment) -> int:
    if segment.info.finished and TOPIC_SEAL in segment.info.channels:
        return segment.info.channels[TOPIC_SEAL]
    if segment.session.tier == "cold":
        return sum(
            int(orjson.loads(m.data).get("cycles", 0))
            for m in segment.iter_messages()
            if m.topic == INDEX_TOPIC
        )
    period = max(1, segment.session.period_ns)
    return max(1, (segment.info.end_ns - segment.info.start_ns) // period + 1)


def _result(
    root: Path, path: Path, segment: Segment, target: Path | None, *, status: Status, detail: str
) -> SegmentResult:
    return SegmentResult(
        source=_rel(root, path),
        target=_rel(root, target) if target is not None else None,
        robot=segment.session.robot_id,
        segment=segment.session.segment,
        source_tier=segment.session.tier,
        cycles=_cycle_estimate(segment),
        bytes_before=segment.info.bytes,
        bytes_after=None,
        status=status,
        detail=detail,
    )


# --- one segment ---------------------------------------------------------------------------


def compact_segment(
    root: Path,
    path: Path,
    segment: Segment,
    tier: str,
    *,
    warm_policy: WarmPolicy,
    cold_options: ColdOptions,
    advance: Callable[[int], None] = lambda _n: None,
    opener: PartialOpener = open_partial,
) -> SegmentResult:
    """Write, verify and swap in the ``tier`` copy of one segment; remove the source last."""
    started = time.perf_counter()
    result = _result(root, path, segment, root / tier / path.name, status="compacted", detail="")
    written = _write_replacement(
        root,
        path,
        segment,
        tier,
        warm_policy=warm_policy,
        cold_options=cold_options,
        advance=advance,
        opener=opener,
    )
    if isinstance(written, str):
        return _failed(result, written, started)
    return _swap_in(root, path, tier, result, full_cycles=written.full_cycles, started=started)


def _failed(result: SegmentResult, detail: str, started: float) -> SegmentResult:
    result.status, result.detail = "failed", detail
    result.seconds = time.perf_counter() - started
    return result


def _write_replacement(
    root: Path,
    path: Path,
    segment: Segment,
    tier: str,
    *,
    warm_policy: WarmPolicy,
    cold_options: ColdOptions,
    advance: Callable[[int], None],
    opener: PartialOpener,
) -> _Written | str:
    """Write the ``tier`` copy of a segment aside as its partial file, fsync it and check that
    it holds exactly what was written; the failure detail (a str) if not, the partial gone."""
    target_dir = root / tier
    target_dir.mkdir(parents=True, exist_ok=True)
    target = target_dir / path.name
    partial = partial_path(target)
    if target.exists():
        return f"{_rel(root, target)} exists already and is not this segment's copy"
    try:
        file = opener(partial)
    except FileExistsError:
        return f"a file not made by compaction is in the way: {_rel(root, partial)}"
    except OSError as err:
        return f"cannot create {_rel(root, partial)}: {err}"
    # From here on the partial is the file this run created: ours to remove on failure.
    try:
        source_sha = file_digest(path)
        with PartialStream(file) as stream:
            if tier == "cold":
                written = _write_cold(segment, stream, source_sha, cold_options, advance)
            else:
                written = _write_warm(segment, stream, source_sha, warm_policy, advance)
        _check_written(segment, partial, written)
    except (VerificationError, LogReadError, ColdFormatError, SegmentWriteError, OSError) as err:
        with contextlib.suppress(OSError):
            partial.unlink()
        return str(err)
    return written


def _swap_in(
    root: Path,
    path: Path,
    tier: str,
    result: SegmentResult,
    *,
    full_cycles: int | None,
    started: float,
) -> SegmentResult:
    """Rename a verified partial into place, update the catalog, and only then remove the
    source (each step fsynced)."""
    target_dir = root / tier
    target = target_dir / path.name
    partial = partial_path(target)
    try:
        os.replace(partial, target)
    except OSError as err:
        with contextlib.suppress(OSError):
            partial.unlink()
        return _failed(result, str(err), started)
    fsync_dir(target_dir)
    result.detail = _refresh(root)
    path.unlink()
    fsync_dir(path.parent)
    result.bytes_after = target.stat().st_size
    result.full_cycles = full_cycles
    result.seconds = time.perf_counter() - started
    return result


def _write_in_worker(
    root: Path, path: Path, tier: str, settings: tuple[WarmPolicy, ColdOptions, PartialOpener]
) -> int | str | None:
    """In a worker process: ``_write_replacement`` of one segment, which the worker opens and
    reads from disk itself (nothing but paths and options crosses the process boundary).
    Returns the warm tier's full cycle count (None for cold), or the failure detail (str)."""
    warm_policy, cold_options, opener = settings
    try:
        segment = Segment(path)
    except LogReadError as err:
        return str(err)
    written = _write_replacement(
        root,
        path,
        segment,
        tier,
        warm_policy=warm_policy,
        cold_options=cold_options,
        advance=lambda _n: None,
        opener=opener,
    )
    return written if isinstance(written, str) else written.full_cycles


def _compact_in_workers(
    root: Path,
    plan: list[tuple[Path, Segment]],
    settings: _Settings,
    advance: Callable[[int, str], None],
) -> Iterator[tuple[Path, SegmentResult]]:
    """Compact the planned segments in ``settings.cold.jobs`` worker processes, one segment
    per task. Each worker writes and checks its segment's partial file; this process then
    swaps the replacements in, one at a time and in plan order, exactly as ``compact_segment``
    does (rename, fsync, catalog, remove the source)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # spawn: a worker never inherits the threads or locks of an embedding process
    pool = ProcessPoolExecutor(
        min(settings.cold.jobs, len(plan)),
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_exit_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        jobs = [
            (
                path,
                segment,
                time.perf_counter(),
                pool.submit(
                    _write_in_worker,
                    root,
                    path,
                    settings.tier,
                    (settings.warm, settings.cold, settings.opener),
                ),
            )
            for path, segment in plan
        ]
        for path, segment, started, job in jobs:
            target = root / settings.tier / path.name
            result = _result(root, path, segment, target, status="compacted", detail="")
            outcome = job.result()
            if isinstance(outcome, str):
                yield path, _failed(result, outcome, started)
                continue
            yield (
                path,
                _swap_in(root, path, settings.tier, result, full_cycles=outcome, started=started),
            )
            advance(result.cycles, path.name)
    finally:
        pool.shutdown(cancel_futures=True)


def _picklable(value: Any) -> bool:
    try:
        pickle.dumps(value)
    except (pickle.PicklingError, TypeError, AttributeError):
        return False
    return True


def _tier_session(segment: Segment, tier: str) -> SessionInfo:
    return replace(segment.session, tier=tier)


def _tier_metadata(segment: Segment, tier: str, source_sha: str, **extra: str) -> dict[str, str]:
    lossy = (
        "true"
        if tier == "warm" or segment.metadata.get(TIER_METADATA, {}).get("lossy") == "true"
        else "false"
    )
    note = (
        "lossy: routine cycles are summaries (seal kept in full; layer messages pruned; "
        "sensor readings dropped unless keep_readings); flagged cycles and their context are "
        "byte-exact copies"
        if tier == "warm"
        else "lossless re-encoding of its source: decoding gives back every message byte for byte"
    )
    if tier == "cold" and lossy == "true":
        note += " (the source was a lossy warm segment)"
    # Whether the robot's logger closed the original (verify then requires its closing
    # checkpoint): a hot source says so itself, a compacted one passes it on.
    finished = (
        str(segment.info.finished).lower()
        if segment.session.tier == "hot"
        else segment.metadata.get(TIER_METADATA, {}).get("source_finished")
    )
    return {
        "tier": tier,
        "source_tier": segment.session.tier,
        "source_sha256": source_sha,
        "source_bytes": str(segment.info.bytes),
        "lossy": lossy,
        "note": note,
        **({} if finished is None else {"source_finished": finished}),
        **extra,
    }


class _Tally:
    """A running digest of a message stream: what was written, or what is read back."""

    def __init__(self) -> None:
        self._sha = hashlib.sha256()
        self.count = 0

    def add(self, topic: str, sequence: int, log_time_ns: int, data: bytes) -> None:
        self._sha.update(b"%d %d %d %d " % (len(topic), sequence, log_time_ns, len(data)))
        self._sha.update(topic.encode())
        self._sha.update(data)
        self.count += 1

    @property
    def digest(self) -> str:
        return self._sha.hexdigest()


def _batch_digest(rows: Iterable[tuple[str, int, int, bytes]]) -> str:
    """SHA-256 of a batch of messages: their (topic, sequence, log time, size) and data."""
    rows = list(rows)
    sha = hashlib.sha256(orjson.dumps([(t, s, at, len(d)) for t, s, at, d in rows]))
    sha.update(b"".join(row[3] for row in rows))
    return sha.hexdigest()


@dataclass(slots=True)
class _Written:
    """What a tier writer wrote (a digest per chunk) and, for warm, the seals it carried."""

    batches: list[tuple[int, str]]
    seals: _Tally
    full_cycles: int | None = None


class _TallyWriter:
    """A SegmentWriter that records a digest of every batch (chunk) it writes."""

    def __init__(self, writer: SegmentWriter) -> None:
        self.writer = writer
        self.batches: list[tuple[int, str]] = []
        self._topics: dict[int, str] = {}

    def channel(self, topic: str, **kwargs: Any) -> int:
        channel = self.writer.channel(topic, **kwargs)
        self._topics[channel] = topic
        return channel

    def write_batch(self, batch: list[OutMessage]) -> None:
        self.writer.write_batch(batch)
        topics = self._topics
        rows = ((topics[m.channel_id], m.sequence, m.log_time_ns, m.data) for m in batch)
        self.batches.append((len(batch), _batch_digest(rows)))


def _as_tuples(messages: list[RawMessage]) -> list[tuple[str, int, int, bytes]]:
    return [(m.topic, m.sequence, m.log_time_ns, m.data) for m in messages]


def _exit_with_parent(parent: int) -> None:
    """In a worker: exit when the compacting process is gone (killed with -9, it cannot
    shut its pool down, and an idle worker would wait for work forever). A worker writes a
    partial file, so it stops soon: the next run may start (the lock died with the parent),
    and a worker still busy then could at worst remove the partial of the same name and make
    that run fail the segment (a worker never renames a file and never touches a source)."""
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.1)
        os._exit(1)

    threading.Thread(target=watch, name="trace-compact-parent-watch", daemon=True).start()


def _open_writer(
    segment: Segment, stream: PartialStream, tier: str, **options: Any
) -> _TallyWriter:
    """A SegmentWriter on a partial file whose first write carries compaction's marker."""
    marker = {"partial": segment.path.name, "tier": tier}
    # The logger's cost statistics describe the source's cycles, which every tier keeps (in
    # full or summarised): `trace-audit metrics` reads them from whichever copy it opens.
    carried = [
        (name, segment.metadata[name]) for name in (TIMING_METADATA,) if name in segment.metadata
    ]
    writer = SegmentWriter(
        cast(BinaryIO, stream),  # PartialStream has every method SegmentWriter uses
        _tier_session(segment, tier),
        extra_metadata=[(PARTIAL_METADATA, marker), *carried],
        **options,
    )
    stream.release()
    return _TallyWriter(writer)


def _write_cold(
    segment: Segment,
    stream: PartialStream,
    source_sha: str,
    options: ColdOptions,
    advance: Callable[[int], None],
) -> _Written:
    # Blocks are zstd-compressed already; a second compression of the chunk would only cost time.
    out = _open_writer(segment, stream, "cold", compression="")
    counts = {"blocks": 0, "cycles": 0, "messages": 0, "verbatim": 0}
    # Nothing a compaction makes is cyclic: the cyclic GC would only walk the blocks in
    # flight again and again (reference counting still frees everything).
    with gc_paused():
        _encode_blocks(segment, out, options, counts, advance)
    blocks, cycles = counts["blocks"], counts["cycles"]
    out.writer.add_metadata(
        TIER_METADATA,
        _tier_metadata(
            segment,
            "cold",
            source_sha,
            codec=CODEC,
            block_cycles=str(options.block_cycles),
            blocks=str(blocks),
            cycles=str(cycles),
            messages=str(counts["messages"]),
            verbatim_messages=str(counts["verbatim"]),
        ),
    )
    out.writer.finish()
    return _Written(out.batches, _Tally())


def _encode_blocks(
    segment: Segment,
    out: _TallyWriter,
    options: ColdOptions,
    counts: dict[str, int],
    advance: Callable[[int], None],
) -> None:
    """Encode the segment's blocks, check each against the source, write each as a chunk."""
    block_channel = out.channel(BLOCK_TOPIC, encoding=CODEC, schema=BLOCK_SCHEMA)
    index_channel = out.channel(INDEX_TOPIC, encoding="json", schema=INDEX_SCHEMA)
    source_tier = segment.session.tier
    encoder = BlockEncoder(options.level)
    source = iter_blocks(segment.iter_messages(), options.block_cycles)
    for number, block in enumerate(source):
        kept, plain, positions = split_plain(block)
        raw_before = encoder.raw_messages
        data, _decoded = encoder.encode_checked(kept, source_tier, positions)
        # The block, decoded again with its plain messages put back, must be the source
        # block as it was read, message for message. encode_checked proved that the block
        # decodes to ``kept``, message for message, with its plain ones at ``positions``;
        # this catches a pipeline that gave it something else. Comparing ``kept`` itself
        # rather than its decoded copies proves the same and finds the source's own objects
        # in both lists, so == compares pointers (~6 us a cycle, 1.5% of a compaction).
        if list(merge_plain(kept, plain, positions)) != block:
            raise VerificationError(f"block {number} does not decode to the source messages")
        entry = index_entry(block)
        first = min(m.log_time_ns for m in block)
        last = max(m.log_time_ns for m in block)
        out.write_batch(
            [
                *(
                    OutMessage(out.channel(m.topic), m.sequence, m.log_time_ns, m.data)
                    for m in plain
                ),
                OutMessage(block_channel, number, first, data),
                OutMessage(index_channel, number, last, orjson.dumps(entry)),
            ]
        )
        counts["blocks"] += 1
        counts["cycles"] += entry["cycles"]
        counts["messages"] += len(block) - len(plain)
        counts["verbatim"] += encoder.raw_messages - raw_before
        advance(entry["cycles"])


def _write_warm(
    segment: Segment,
    stream: PartialStream,
    source_sha: str,
    policy: WarmPolicy,
    advance: Callable[[int], None],
) -> _Written:
    out = _open_writer(segment, stream, "warm", level=WARM_LEVEL)
    out.channel(SUMMARY_TOPIC, schema=SUMMARY_SCHEMA)
    seals = _Tally()

    def source() -> Iterator[RawMessage]:
        # The seals of the source, tallied as they are read, to check the copy independently.
        for msg in segment.iter_messages():
            if msg.topic == TOPIC_SEAL:
                seals.add(msg.topic, msg.sequence, msg.log_time_ns, msg.data)
            yield msg

    batch: list[OutMessage] = []
    in_batch = full = summaries = 0
    for cycle in warm_cycles(source(), policy, segment.session.period_ns):
        for msg in cycle.messages:
            channel = _channel(out, msg.topic)
            batch.append(OutMessage(channel, msg.sequence, msg.log_time_ns, msg.data))
        sealed = cycle.messages[-1].topic == TOPIC_SEAL  # not the closing checkpoint alone
        full += cycle.full and sealed
        summaries += not cycle.full
        in_batch += 1
        if in_batch >= WARM_CHUNK_CYCLES:
            out.write_batch(batch)
            advance(in_batch)
            batch, in_batch = [], 0
    if batch:
        out.write_batch(batch)
        advance(in_batch)
    out.writer.add_metadata(
        TIER_METADATA,
        _tier_metadata(
            segment,
            "warm",
            source_sha,
            full_cycles=str(full),
            summary_cycles=str(summaries),
            **policy.to_metadata(),
        ),
    )
    out.writer.finish()
    return _Written(out.batches, seals, full)


def _check_written(source: Segment, partial: Path, written: _Written) -> None:
    """The file on disk holds exactly what was written (and verified), nothing else."""
    target = Segment(partial)
    if replace(target.session, tier=source.session.tier) != source.session:
        raise VerificationError(f"{partial.name}: session record differs from the source's")
    seals = _Tally()
    messages = target.iter_messages()
    for count, want in written.batches:
        batch = list(islice(messages, count))
        for msg in batch:
            if msg.topic == TOPIC_SEAL:
                seals.add(msg.topic, msg.sequence, msg.log_time_ns, msg.data)
        if len(batch) != count or _batch_digest(_as_tuples(batch)) != want:
            raise VerificationError(f"{partial.name}: the file does not hold what was written")
    if next(messages, None) is not None:
        raise VerificationError(f"{partial.name}: the file holds more than was written")
    if target.session.tier == "warm":
        if (seals.count, seals.digest) != (written.seals.count, written.seals.digest):
            raise VerificationError(f"{partial.name}: seals differ from the source's")
    elif (target.info.start_ns, target.info.end_ns) != (source.info.start_ns, source.info.end_ns):
        raise VerificationError(f"{partial.name}: time range differs from the source's")


def _channel(writer: _TallyWriter, topic: str) -> int:
    if topic.startswith("/trace/") and topic not in MESSAGE_MODELS and topic != SUMMARY_TOPIC:
        # A /trace topic this version has no schema for (a newer writer): keep it, schemaless.
        return writer.channel(topic, schema=("trace.Unknown", "", b""))
    return writer.channel(topic)


# --- verification --------------------------------------------------------------------------


def verify_replacement(source: Segment, replacement: Path) -> None:
    """Raise ``VerificationError`` unless ``replacement`` is exactly what ``source`` becomes."""
    target = Segment(replacement)
    tier = target.session.tier
    if replace(target.session, tier=source.session.tier) != source.session:
        raise VerificationError(f"{replacement.name}: session record differs from the source's")
    if tier == "cold":
        _same(source.iter_messages(), iter_decoded(target.iter_messages()), replacement)
        if (target.info.start_ns, target.info.end_ns) != (source.info.start_ns, source.info.end_ns):
            raise VerificationError(f"{replacement.name}: time range differs from the source's")
    elif tier == "warm":
        policy = WarmPolicy.from_metadata(target.metadata.get(TIER_METADATA, {}))
        expected = (
            m
            for c in warm_cycles(source.iter_messages(), policy, source.session.period_ns)
            for m in c.messages
        )
        _same(expected, target.iter_messages(), replacement)
        # Independently of how summaries are made: every seal must be there, byte for byte.
        _same(
            (m for m in source.iter_messages() if m.topic == TOPIC_SEAL),
            (m for m in target.iter_messages() if m.topic == TOPIC_SEAL),
            replacement,
        )
    else:
        raise VerificationError(f"{replacement.name}: tier {tier!r} is not a compaction target")


def _same(expected: Iterator[RawMessage], actual: Iterator[RawMessage], path: Path) -> None:
    for count, (want, got) in enumerate(zip_longest(expected, actual)):
        if want != got:
            if want is None or got is None:
                raise VerificationError(f"{path.name}: message count differs from the source's")
            raise VerificationError(
                f"{path.name}: message {count} ({want.topic} at {want.log_time_ns}) differs"
            )


def chain_problems(segment: Segment, limit: int = 10, key: PublicKey | None = None) -> list[str]:
    """What ``verify`` finds in one segment on its own (its chain entering where its
    ``trace.session`` says), one line each; empty when it verifies."""
    report = verify(Log([segment], segment.path.parent), key=key)
    return [f"{f.kind}: {f.message}" for f in report.findings[:limit]]


# --- leftovers of a killed run ---------------------------------------------------------------


def recover(root: Path, *, dry_run: bool = False, key: PublicKey | None = None) -> list[Leftover]:
    """Finish or undo what a killed compaction left in ``root`` (report only, if dry run).

    Unfinished writes are discarded only when provably compaction's own (``partial_owner``);
    a segment in two tiers is settled by ``_settle``, never at the cost of its last good copy.
    """
    done: list[Leftover] = []
    for tier in TIERS:
        directory = root / tier
        if not directory.is_dir():
            continue
        for partial in sorted(directory.glob(f"*{PARTIAL_SUFFIX}")):
            if not partial.is_file():
                continue
            why = partial_owner(partial)
            if why is not None:
                done.append(Leftover(_rel(root, partial), f"left alone: {why}"))
                continue
            if not dry_run:
                partial.unlink()
                fsync_dir(directory)
            done.append(Leftover(_rel(root, partial), "unfinished write discarded"))
    by_name: dict[str, list[Path]] = {}
    for path in segment_files(root):
        by_name.setdefault(path.name, []).append(path)
    for copies in by_name.values():
        if len(copies) >= 2:
            # TIERS order: the least compacted copy is the source, the next one its
            # replacement; a third copy (never made by compact) waits for the next run.
            done.append(_settle(root, copies[0], copies[1], dry_run, key))
    return done


@dataclass(slots=True)
class _Copy:
    """One copy of a segment as ``_settle`` sees it."""

    path: Path
    segment: Segment | None
    report: VerifyReport | None
    problem: str = ""

    @property
    def clean(self) -> bool:
        """Opened, read to the end, and ``verify`` finds nothing in it."""
        return self.report is not None and self.report.ok

    def why_not(self) -> str:
        if self.report is None:
            return self.problem
        first = self.report.findings[0]
        return f"{first.kind}: {first.message}"


def _examine(path: Path, key: PublicKey | None) -> _Copy:
    try:
        segment = Segment(path)
    except LogReadError as err:
        return _Copy(path, None, None, f"cannot be opened ({err.reason})")
    return _Copy(path, segment, verify(Log([segment], path.parent), key=key))


def _settle(
    root: Path, source_path: Path, replacement: Path, dry_run: bool, key: PublicKey | None
) -> Leftover:
    """Settle a segment found in two tiers, keeping a copy that verifies.

    - the replacement is exactly what the source becomes: the source is removed;
    - the source is damaged (it opens, but parts cannot be read) and the replacement is a
      lossless copy of it that verifies and holds every message still readable in the
      source: the source is removed (the compaction is completed from the good copy);
    - the source verifies and the replacement does not (damaged, or findings): the
      replacement, compaction's own file, is discarded and the segment compacted again;
    - anything else (both verify but differ, neither verifies, a lossy replacement of a
      damaged source, a source that cannot be opened): both are held for a human.
    """
    src_rel, rep_rel = _rel(root, source_path), _rel(root, replacement)
    source = _examine(source_path, key)
    copy = _examine(replacement, key)
    mismatch = ""
    if source.segment is not None and copy.segment is not None:
        try:
            verify_replacement(source.segment, replacement)
        except (VerificationError, LogReadError, ColdFormatError) as err:
            mismatch = str(err)
        else:
            _remove(source_path, dry_run)
            return Leftover(src_rel, f"replacement {rep_rel} verified; source removed")
    if copy.clean and _completes(source, copy):
        _remove(source_path, dry_run)
        return Leftover(
            src_rel,
            f"source damaged ({source.why_not()}); verified replacement {rep_rel} kept and "
            "holds everything still readable in it; source removed",
        )
    if source.clean and not copy.clean and _own_copy(copy):
        _remove(replacement, dry_run)
        why = copy.why_not() if copy.report is None or not copy.report.ok else mismatch
        return Leftover(rep_rel, f"replacement did not verify ({why}); discarded")
    if source.clean and copy.clean:
        why = f"both verify but differ ({mismatch})"
    else:
        parts = [f"{c.path.parent.name}: {c.why_not()}" for c in (source, copy) if not c.clean]
        why = "; ".join(parts) or mismatch
    return Leftover(src_rel, f"held: copies in {src_rel} and {rep_rel} kept ({why})")


def _completes(source: _Copy, copy: _Copy) -> bool:
    """Whether ``copy`` (verified) can stand in for a damaged ``source``: a lossless copy of
    the same segment that holds every message the source still yields, in order."""
    if source.segment is None or copy.segment is None or source.report is None:
        return False
    if not any(f.kind == "damaged" for f in source.report.findings):
        return False  # readable, but different: not decay
    meta = copy.segment.metadata.get(TIER_METADATA, {})
    if copy.segment.session.tier != "cold" or meta.get("lossy") != "false":
        return False
    if replace(copy.segment.session, tier=source.segment.session.tier) != source.segment.session:
        return False
    try:
        decoded = iter_decoded(copy.segment.iter_messages())
        for want in _readable_messages(source.segment):
            if not any(got == want for got in decoded):
                return False
    except (LogReadError, ColdFormatError):
        return False
    return True


def _readable_messages(segment: Segment) -> Iterator[RawMessage]:
    """Every message of a damaged segment that can still be read, chunk by chunk."""
    if segment.loose:
        yield from segment.loose
    for chunk in segment.chunks():
        try:
            messages = segment.chunk_messages(chunk.offset)
        except LogReadError:
            continue
        yield from messages


def _own_copy(copy: _Copy) -> bool:
    """A finished replacement is compaction's own when it says so: its trace.session names a
    compacted tier and it carries the trace.tier record (or the partial-file marker)."""
    if copy.segment is not None:
        return copy.segment.session.tier in ("warm", "cold") and bool(
            copy.segment.metadata.get(TIER_METADATA)
        )
    return compaction_marker(copy.path) == copy.path.name


def _remove(path: Path, dry_run: bool) -> None:
    if not dry_run:
        path.unlink()
        fsync_dir(path.parent)


# --- retention -------------------------------------------------------------------------------


def _retention(
    root: Path, cutoff_ns: int, robot: str | None, dry_run: bool, key: PublicKey | None
) -> list[RetentionResult]:
    """Delete old cold segments that ``verify`` finds clean; hold every other one."""
    out: list[RetentionResult] = []
    segments, problems = open_segments(segment_files(root))
    for problem in problems:
        if problem.path.parent.name == "cold":
            rel = _rel(root, problem.path)
            out.append(RetentionResult(rel, 0, "kept", f"held: unreadable ({problem.reason})"))
    candidates = [
        s
        for s in segments
        if s.session.tier == "cold"
        and s.path.parent.name == "cold"
        and (robot is None or s.session.robot_id == robot)
        and s.info.end_ns < cutoff_ns
    ]
    for robot_id in sorted({s.session.robot_id for s in candidates}):
        mine = [s for s in candidates if s.session.robot_id == robot_id]
        chain = [s for s in segments if s.session.robot_id == robot_id]
        out += _retire(root, mine, chain, dry_run, key)
    return out


def _retire(
    root: Path,
    candidates: list[Segment],
    chain: list[Segment],
    dry_run: bool,
    key: PublicKey | None,
) -> list[RetentionResult]:
    """One robot's old cold segments: verify its chain up to the newest of them, delete each
    one that verify finds nothing in, whose successor continues from its last seal."""
    last = max(s.session.segment for s in candidates)
    report = verify(Log([s for s in chain if s.session.segment <= last], root), key=key)
    summaries = {Path(s.path): s for s in report.segments}
    named = {f.segment for f in report.findings}
    out: list[RetentionResult] = []
    for segment in sorted(candidates, key=lambda s: s.session.segment):
        rel, end = _rel(root, segment.path), segment.info.end_ns
        summary = summaries[segment.path]
        why = _retention_hold(segment, summary, named, chain, report)
        if why:
            out.append(RetentionResult(rel, end, "kept", why))
            continue
        if dry_run:
            out.append(RetentionResult(rel, end, "would delete"))
            continue
        try:
            _record_retired(root, segment.path, segment, summary.last_seal)
        except OSError as err:
            out.append(RetentionResult(rel, end, "kept", f"cannot record the deletion: {err}"))
            continue
        segment.path.unlink()
        fsync_dir(segment.path.parent)
        out.append(RetentionResult(rel, end, "deleted"))
    return out


def _retention_hold(
    segment: Segment,
    summary: SegmentSummary,
    named: set[str],
    chain: list[Segment],
    report: VerifyReport,
) -> str:
    """Why retention must keep ``segment`` ("" when nothing stops it)."""
    name = f"cold/{segment.path.name}"
    if not summary.ok or name in named:
        first = next((f for f in report.findings if f.segment == name), None)
        return "held: findings" + (f" ({first.kind}: {first.message})" if first else "")
    if summary.copy or any(
        s.path != segment.path and s.path.name == segment.path.name for s in chain
    ):
        return "held: the segment is in two tiers"
    after = [s for s in chain if s.session.segment == segment.session.segment + 1]
    tail = summary.last_seal or segment.session.prev_seal  # an empty segment passes it on
    if any(s.session.prev_seal != tail for s in after):
        return "held: the next segment does not continue its chain"
    return ""


def _record_retired(root: Path, path: Path, segment: Segment, last_seal: str | None) -> None:
    line = {
        "path": _rel(root, path),
        "robot": segment.session.robot_id,
        "segment": segment.session.segment,
        "start_ns": segment.info.start_ns,
        "end_ns": segment.info.end_ns,
        "prev_seal": segment.session.prev_seal,
        "last_seal": last_seal,
        "sha256": file_digest(path),
        "deleted_at_ns": time.time_ns(),
    }
    with open(root / RETENTION_LOG, "ab") as log:
        log.write(orjson.dumps(line) + b"\n")
        log.flush()
        os.fsync(log.fileno())


def _rel(root: Path, path: Path) -> str:
    try:
        return path.relative_to(root).as_posix()
    except ValueError:
        return str(path)


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0
