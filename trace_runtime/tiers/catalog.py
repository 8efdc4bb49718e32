"""The catalog of a log root: one row per segment file, rebuildable from the files.

A log root holds ``hot/``, ``warm/`` and ``cold/`` and a ``catalog.json`` that indexes every
segment in them: robot, tier, segment number, time range, cycle range and count, the
digests of its first and last seal (and the previous segment's last seal it links to), the
SHA-256 of the file and its size. The files are the truth: ``refresh_catalog`` rebuilds the
catalog from them and replaces ``catalog.json`` atomically; ``load_catalog`` only reads it.

A root travels, so its catalog is a hint, never authority: a row is reused by a rebuild only
for its digests (the costly part), and only when the file still has the row's size and mtime
and its own summary confirms the row's robot, tier, segment, times and state;
``refresh_catalog(rehash=True)`` recomputes every digest too. Whoever needs a digest as
evidence (the fleet index, retention's journal) takes it from the file itself.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Collection, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import orjson

from trace_runtime.boundary import (
    read_side_file,
    remove_stale_partials,
    tier_folder,
    write_atomic,
)
from trace_runtime.chain import digest
from trace_runtime.errors import LogReadError
from trace_runtime.reading.catalog_rows import CATALOG_FORMAT, CATALOG_NAME, read_catalog_file
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.segment_files import find_segment_files
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.session import TIER_METADATA, TIERS
from trace_runtime.tier_formats.cold import INDEX_TOPIC
from trace_runtime.tiers._files import require_root

log = logging.getLogger(__name__)

_MAX_PROBLEMS = 10_000
"""The most problems a stored catalog is read with (each is a line for a person)."""


@dataclass(frozen=True, slots=True)
class CatalogEntry:
    """What the catalog knows about one segment file."""

    path: str
    """Path relative to the log root, with forward slashes (``cold/amr-1_000003.mcap``)."""
    robot: str
    tier: str
    segment: int
    start_ns: int
    end_ns: int
    first_cycle: int | None
    last_cycle: int | None
    cycles: int
    first_seal: str | None
    last_seal: str | None
    prev_seal: str
    sha256: str
    bytes: int
    finished: bool
    lossy: bool
    mtime_ns: int = 0

    @property
    def name(self) -> str:
        return self.path.rsplit("/", 1)[-1]


@dataclass(slots=True)
class Catalog:
    """Every segment of a log root, ordered by robot, segment number and tier."""

    root: Path
    entries: list[CatalogEntry] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    """Files under the tier directories that could not be read as TRACE segments."""

    def for_robot(self, robot: str) -> list[CatalogEntry]:
        return [e for e in self.entries if e.robot == robot]

    def get(self, path: Path | str) -> CatalogEntry | None:
        """The entry of a segment file (absolute, or relative to the root)."""
        rel = _relative(self.root, Path(path))
        return next((e for e in self.entries if e.path == rel), None)

    @property
    def newest_end_ns(self) -> int | None:
        return max((e.end_ns for e in self.entries), default=None)

    def to_json(self) -> bytes:
        body = {
            "format": CATALOG_FORMAT,
            "segments": [asdict(e) for e in self.entries],
            "problems": self.problems,
        }
        return orjson.dumps(body, option=orjson.OPT_INDENT_2) + b"\n"


def load_catalog(root: str | Path, paths: Collection[str] | None = None) -> Catalog | None:
    """The catalog stored in ``root`` as last written, or None if there is none, or none that
    can be read (not a regular file, over the side-file bounds, not a catalog: a warning).

    ``paths``: keep only the rows of these files (relative to the root), so a catalog full
    of rows naming files that are not there costs no more than its bytes; its problems are
    then not read (a rebuild finds its own). At most ``_MAX_PROBLEMS`` problems are kept."""
    root = Path(root)
    try:
        stored = read_catalog_file(root)
    except LogReadError as err:
        log.warning("%s; the catalog is rebuilt from the files", err)
        return None
    if stored is None:
        return None
    wanted = None if paths is None else set(paths)
    entries = stored.rows(CatalogEntry, None if wanted is None else lambda e: e.path in wanted)
    problems = [] if wanted is not None else stored.problems_listed(_MAX_PROBLEMS)
    if entries is None or problems is None:
        return None
    return Catalog(root, entries, problems)


def refresh_catalog(root: str | Path, *, write: bool = True, rehash: bool = False) -> Catalog:
    """Rebuild the catalog from the segment files; rewrite ``catalog.json`` if it changed.

    ``rehash``: recompute every file's digests instead of reusing a confirmed row's."""
    root = Path(root)
    require_root(root)
    files = {_relative(root, path): path for path in segment_files(root)}
    old = None if rehash else load_catalog(root, files)
    known = {e.path: e for e in old.entries} if old else {}
    entries: list[CatalogEntry] = []
    problems: list[str] = []
    for rel, path in files.items():
        try:
            entries.append(_confirmed(root, path, known.get(rel)))
        except FileNotFoundError:
            continue  # removed while we looked
        except LogReadError as err:
            problems.append(f"{rel}: {err.reason}")
    entries.sort(key=lambda e: (e.robot, e.segment, TIERS.index(e.tier) if e.tier in TIERS else 9))
    catalog = Catalog(root, entries, problems)
    if write:
        data = catalog.to_json()
        try:
            current = read_side_file(root / CATALOG_NAME)
        except LogReadError:
            current = None  # write_atomic refuses a name held by anything but a file
        if data != current:
            write_atomic(root / CATALOG_NAME, data)
        else:
            remove_stale_partials(root / CATALOG_NAME)
    return catalog


def _confirmed(root: Path, path: Path, cached: CatalogEntry | None) -> CatalogEntry:
    """``path``'s entry: ``cached`` when the file still has its size and mtime and its own
    summary says what the row says; otherwise described afresh from the file."""
    stat = path.stat()
    if cached is None or cached.bytes != stat.st_size or cached.mtime_ns != stat.st_mtime_ns:
        return describe_segment(root, path)
    segment = Segment(path)
    info, session = segment.info, segment.session
    facts = (session.robot_id, session.tier, session.segment, session.prev_seal)
    times = (info.start_ns, info.end_ns, info.finished)
    if facts != (cached.robot, cached.tier, cached.segment, cached.prev_seal) or times != (
        cached.start_ns,
        cached.end_ns,
        cached.finished,
    ):
        return describe_segment(root, path, segment)
    return cached


def segment_files(root: Path) -> list[Path]:
    """Every segment file directly in the tier directories of ``root``, as
    ``segment_files.find_segment_files`` finds them (writes in progress excluded); a tier folder
    that is a symbolic link is refused (``boundary.tier_folder``)."""
    files: list[Path] = []
    for tier in TIERS:
        directory = tier_folder(root, tier)
        if directory is not None:
            files += [p for p in find_segment_files(directory) if p.parent == directory]
    return files


def describe_segment(root: Path, path: Path, segment: Segment | None = None) -> CatalogEntry:
    """A catalog entry for one segment file (reads its summary and first/last seal)."""
    opened = segment or Segment(path)
    info = opened.info
    session = opened.session
    first_cycle = last_cycle = None
    first_seal = last_seal = None
    cycles = 0
    if session.tier == "cold":
        for msg in opened.iter_messages():
            if msg.topic != INDEX_TOPIC:
                continue
            entry = orjson.loads(msg.data)
            cycles += int(entry.get("cycles", 0))
            if entry.get("first_seal") and first_seal is None:
                first_seal, first_cycle = entry["first_seal"], entry.get("first_cycle")
            if entry.get("last_seal"):
                last_seal, last_cycle = entry["last_seal"], entry.get("last_cycle")
    else:
        first = _first_seal(opened.iter_cycles())
        last = _first_seal(opened.iter_cycles(reverse=True))
        if first is not None and last is not None:
            (first_cycle, first_seal), (last_cycle, last_seal) = first, last
        if info.finished:
            cycles = info.channels.get(TOPIC_SEAL, 0)
        else:
            cycles = sum(1 for c in opened.iter_cycles() if c.sealed)
    tier_meta = info.metadata.get(TIER_METADATA, {})
    stat = path.stat()
    return CatalogEntry(
        path=_relative(root, path),
        robot=session.robot_id,
        tier=session.tier,
        segment=session.segment,
        start_ns=info.start_ns,
        end_ns=info.end_ns,
        first_cycle=first_cycle,
        last_cycle=last_cycle,
        cycles=cycles,
        first_seal=first_seal,
        last_seal=last_seal,
        prev_seal=session.prev_seal,
        sha256=file_digest(path),
        bytes=stat.st_size,
        finished=info.finished,
        lossy=tier_meta.get("lossy") == "true",
        mtime_ns=stat.st_mtime_ns,
    )


def _first_seal(cycles: Iterable[Any]) -> tuple[int, str] | None:
    for cycle in cycles:
        data = cycle.payloads.get(TOPIC_SEAL)
        if data is not None:
            return cycle.cycle, digest(data)
    return None


def file_digest(path: Path) -> str:
    """SHA-256 of a whole file, read in 1 MiB pieces."""
    sha = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(1 << 20):
            sha.update(block)
    return sha.hexdigest()


def _relative(root: Path, path: Path) -> str:
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return path.as_posix()
