"""A log root's segments as its catalog describes them, opened only when a query reaches them
(``open_log(root, lazy=True)``). The catalog is a hint: it is trusted only when it describes
every file as it is, and each segment's own summary is checked against its row when opened."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import msgspec

from trace_runtime.errors import (
    LogReadError,
    StaleCatalogError,
)
from trace_runtime.read_limits import ReadLimits
from trace_runtime.reading.catalog_rows import read_catalog_file
from trace_runtime.reading.reader import Segment

log = logging.getLogger("trace_runtime")


@dataclass(slots=True)
class Unopened:
    """A segment the catalog describes, opened when a query first reaches it.

    ``start_ns`` and ``end_ns`` are the catalog's; the catalog is a hint, so ``open``
    confirms them (and the robot and segment number) against the file's own summary and
    raises ``StaleCatalogError`` when they differ."""

    path: Path
    robot: str
    segment: int
    start_ns: int
    end_ns: int
    limits: ReadLimits
    opened: Segment | None = field(default=None, repr=False)

    def open(self) -> Segment:
        if self.opened is None:
            segment = Segment(self.path, self.limits)
            own = (segment.session.robot_id, segment.session.segment, segment.start_ns)
            if (*own, segment.end_ns) != (self.robot, self.segment, self.start_ns, self.end_ns):
                log.warning(
                    "%s: the root's catalog.json does not describe it as it is; the catalog "
                    "is ignored",
                    self.path,
                )
                raise StaleCatalogError(str(self.path), "not as the root's catalog.json says")
            self.opened = segment
        return self.opened


Slot = Segment | Unopened


def open_slot(slot: Slot) -> Segment:
    return slot if isinstance(slot, Segment) else slot.open()


def robot_of(slot: Slot) -> str:
    return slot.robot if isinstance(slot, Unopened) else slot.session.robot_id


def chain_key(slot: Slot) -> tuple[int, str]:
    number = slot.segment if isinstance(slot, Unopened) else slot.session.segment
    return number, slot.path.name


def catalogued_slots(
    root: Path, files: Sequence[Path], limits: ReadLimits
) -> list[Unopened] | None:
    """The segments of a log root as its catalog describes them, or None when opening
    them all is the only way to be sure what they are.

    The catalog is trusted only when its rows are exactly the files found, each with the
    size and modification time it had when its row was made, and when every row is simple
    enough that opening the files would add nothing: one copy of each segment (no copy in
    two tiers to choose between), finished, holding sealed cycles, and no file the catalog
    could not read (opening would make it a problem to report).
    """
    catalog = _catalog_rows(root, len(files))
    if catalog is None or len(catalog) != len(files):
        return None
    rows = {row.path: row for row in catalog}
    copies = {(row.robot, row.segment) for row in catalog}
    if len(rows) != len(files) or len(copies) != len(rows):
        return None
    slots: list[Unopened] = []
    for file in files:
        try:
            row = rows.get(file.relative_to(root).as_posix())
            stat = file.stat()
        except (ValueError, OSError):
            return None
        if (
            row is None
            or row.bytes != stat.st_size
            or row.mtime_ns != stat.st_mtime_ns
            or row.finished is not True
            or row.cycles <= 0
        ):
            return None
        slots.append(Unopened(file, row.robot, row.segment, row.start_ns, row.end_ns, limits))
    return slots


class CatalogRow(msgspec.Struct):
    """The fields of a catalog row (``trace_runtime.tiers.catalog.CatalogEntry``) a lazy log
    needs, each checked for type as it is decoded."""

    path: str
    robot: str
    segment: int
    start_ns: int
    end_ns: int
    finished: bool
    cycles: int
    bytes: int
    mtime_ns: int


def _catalog_rows(root: Path, files: int) -> list[CatalogRow] | None:
    """The rows of a root's catalog, or None when there is no catalog that is whole and clean
    or it holds more rows than the root has ``files`` (decoding stops there).

    Read here rather than through ``tiers.catalog.load_catalog`` because importing the tiers
    package loads the writer and the ``mcap`` library (~30 ms) into every ``explain``; a test
    pins these rows to ``load_catalog``'s entries.
    """
    try:
        stored = read_catalog_file(root)
    except LogReadError:
        return None  # a hint that cannot be read is no hint: every segment is opened
    if stored is None or not stored.lists_no_problem():
        return None
    return stored.rows(CatalogRow, limit=files)
