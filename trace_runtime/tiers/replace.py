"""One segment compacted: its copy written and checked (``write``), renamed into the tier,
the catalog updated, and only then the source removed, each step fsynced."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from pathlib import Path

from trace_runtime.boundary import fsync_dir
from trace_runtime.errors import StorageError, TraceError
from trace_runtime.reading.reader import Segment
from trace_runtime.tier_formats.warm import WarmPolicy
from trace_runtime.tiers._files import PartialOpener, open_partial, partial_path
from trace_runtime.tiers.catalog import refresh_catalog
from trace_runtime.tiers.plan import segment_result
from trace_runtime.tiers.report import ColdOptions, SegmentResult
from trace_runtime.tiers.write import write_replacement


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
    result = segment_result(
        root, path, segment, root / tier / path.name, status="compacted", detail=""
    )
    written = write_replacement(
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
        return failed(result, written, started)
    return swap_in(root, path, tier, result, full_cycles=written.full_cycles, started=started)


def failed(result: SegmentResult, detail: str, started: float) -> SegmentResult:
    result.status, result.detail = "failed", detail
    result.seconds = time.perf_counter() - started
    return result


def swap_in(
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
        return failed(result, str(err), started)
    fsync_dir(target_dir)
    result.detail = refresh_quietly(root)
    path.unlink()
    fsync_dir(path.parent)
    result.bytes_after = target.stat().st_size
    result.full_cycles = full_cycles
    result.seconds = time.perf_counter() - started
    return result


def refresh_quietly(root: Path) -> str:
    """Update the catalog; a failure (a full disk) is said, never fatal: the files are the
    truth and the next run rebuilds it."""
    try:
        refresh_catalog(root)
    except StorageError as err:
        return f"catalog not updated ({err.reason})"
    except (TraceError, OSError) as err:
        return f"catalog not updated ({err})"
    return ""
