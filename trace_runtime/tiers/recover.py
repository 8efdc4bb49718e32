"""Finishing or undoing what a killed compaction left in a log root: partial files that are
provably compaction's own are discarded, and a segment found in two tiers is settled
without ever losing its last good copy (copies that cannot be settled are held)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

from trace_runtime.boundary import fsync_dir
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError, LogReadError, VerificationError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.session import TIER_METADATA, TIERS
from trace_runtime.tier_formats.cold import iter_decoded
from trace_runtime.tiers._files import PARTIAL_SUFFIX, compaction_marker, partial_owner
from trace_runtime.tiers.catalog import segment_files
from trace_runtime.tiers.copies import verify_replacement
from trace_runtime.tiers.report import Leftover, rel_path
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.verification import VerifyReport, verify

__all__ = ["recover"]


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
                done.append(Leftover(rel_path(root, partial), f"left alone: {why}"))
                continue
            if not dry_run:
                partial.unlink()
                fsync_dir(directory)
            done.append(Leftover(rel_path(root, partial), "unfinished write discarded"))
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
    src_rel, rep_rel = rel_path(root, source_path), rel_path(root, replacement)
    source = _examine(source_path, key)
    copy = _examine(replacement, key)
    mismatch = ""
    if source.segment is not None and copy.segment is not None:
        try:
            verify_replacement(source.segment, replacement)
        except (VerificationError, LogReadError, ColdFormatError) as err:
            mismatch = str(err)
        else:
            remove_durably(source_path, dry_run)
            return Leftover(src_rel, f"replacement {rep_rel} verified; source removed")
    if copy.clean and _completes(source, copy):
        remove_durably(source_path, dry_run)
        return Leftover(
            src_rel,
            f"source damaged ({source.why_not()}); verified replacement {rep_rel} kept and "
            "holds everything still readable in it; source removed",
        )
    if source.clean and not copy.clean and _own_copy(copy):
        remove_durably(replacement, dry_run)
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


def remove_durably(path: Path, dry_run: bool) -> None:
    if not dry_run:
        path.unlink()
        fsync_dir(path.parent)
