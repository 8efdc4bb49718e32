"""The catalog of a log root: one row per segment file, rebuildable from the files.

A log root holds ``hot/``, ``warm/`` and ``cold/`` and a ``catalog.json`` that indexes every
segment in them: robot, tier, segment number, time range, cycle range and count, the
digests of its first and last seal (and the previous segment's last seal it links to), the
SHA-256 of the file and its size. The files are the truth: ``refresh_catalog`` rebuilds the
catalog from them (re-reading only files whose size or mtime changed) and replaces
``catalog.json`` atomically; ``load_catalog`` only reads it.
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import orjson

from trace_runtime.chain import digest
from trace_runtime.errors import LogReadError
from trace_runtime.logset import find_segment_files
from trace_runtime.reader import Segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.session import TIER_METADATA, TIERS
from trace_runtime.tier_formats.cold import INDEX_TOPIC
from trace_runtime.tiers._files import write_atomic

CATALOG_NAME = "catalog.json"
CATALOG_FORMAT = "trace-catalog-v1"


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


def load_catalog(root: str | Path) -> Catalog | None:
    """The catalog stored in ``root`` as last written, or None if there is none (or unreadable)."""
    root = Path(root)
    try:
        body = orjson.loads((root / CATALOG_NAME).read_bytes())
    except (OSError, orjson.JSONDecodeError):
        return None
    if not isinstance(body, dict) or body.get("format") != CATALOG_FORMAT:
        return None
    try:
        entries = [CatalogEntry(**row) for row in body.get("segments", [])]
    except TypeError:
        return None
    return Catalog(root, entries, [str(p) for p in body.get("problems", [])])


def refresh_catalog(root: str | Path, *, write: bool = True) -> Catalog:
    """Rebuild the catalog from the segment files; rewrite ``catalog.json`` if it changed."""
    root = Path(root)
    if not root.is_dir():
        raise LogReadError(str(root), "not a log root (no such directory)")
    old = load_catalog(root)
    known = {e.path: e for e in old.entries} if old else {}
    entries: list[CatalogEntry] = []
    problems: list[str] = []
    for path in segment_files(root):
        rel = _relative(root, path)
        try:
            stat = path.stat()
        except OSError:
            continue  # removed while we looked
        cached = known.get(rel)
        if (
            cached is not None
            and cached.bytes == stat.st_size
            and cached.mtime_ns == stat.st_mtime_ns
        ):
            entries.append(cached)
            continue
        try:
            entries.append(describe_segment(root, path))
        except LogReadError as err:
            problems.append(f"{rel}: {err.reason}")
    entries.sort(key=lambda e: (e.robot, e.segment, TIERS.index(e.tier) if e.tier in TIERS else 9))
    catalog = Catalog(root, entries, problems)
    if write:
        data = catalog.to_json()
        current = None
        with contextlib.suppress(OSError):
            current = (root / CATALOG_NAME).read_bytes()
        if data != current:
            write_atomic(root / CATALOG_NAME, data)
    return catalog


def segment_files(root: Path) -> list[Path]:
    """Every segment file directly in the tier directories of ``root``, as
    ``logset.find_segment_files`` finds them (writes in progress excluded)."""
    files: list[Path] = []
    for tier in TIERS:
        directory = root / tier
        if directory.is_dir():
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
