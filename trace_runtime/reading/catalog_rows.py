"""The rows of a log root's ``catalog.json``, read in memory bounded by the rows a caller keeps.

The catalog is a side file a root's sender may have crafted: 64 MiB of rows naming files that
do not exist (ghost rows, dropped by every reader) cost ~375 MB when parsed whole into dicts.
Here the top level is decoded with its ``segments`` and ``problems`` arrays left as views into
the file's bytes, then the array's elements are decoded one at a time and only those the
caller keeps stay in memory: the cost is the file's bytes plus the rows kept.

A row is a flat JSON object and a problem a string (the format nests nothing deeper), so an
element that is neither, or a row not of the caller's type, makes the file not a catalog
(None): the catalog is a hint, rebuilt from the segment files when it cannot be used. The
writer is ``trace_runtime.tiers.catalog``.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import msgspec

from trace_runtime.boundary import read_side_file
from trace_runtime.errors import InputError, LogLimitError, LogReadError

__all__ = ["CATALOG_FORMAT", "CATALOG_NAME", "CatalogFile", "read_catalog_file"]

CATALOG_NAME = "catalog.json"
CATALOG_FORMAT = "trace-catalog-v1"

R = TypeVar("R")


class _Top(msgspec.Struct):
    format: str
    segments: msgspec.Raw
    problems: msgspec.Raw = msgspec.Raw(b"[]")


# Inside an array msgspec has already checked is valid JSON: where it opens, what follows an
# element (a comma, or the closing bracket at the end), a string, and a flat object exactly
# (strings may hold braces; possessive quantifiers, so a match is one pass over its bytes).
_OPEN = re.compile(rb"\s*\[\s*")
_AFTER = re.compile(rb"\s*(?:,\s*|(\])\s*\Z)")
_EMPTY = re.compile(rb"\s*\[\s*\]\s*\Z")
_BRACE = re.compile(rb"\}")
_STRING = re.compile(rb'"(?:[^"\\]++|\\.)*+"')
_FLAT_OBJECT = re.compile(rb'\{(?:[^{}\[\]"]++|"(?:[^"\\]++|\\.)*+")*+\}')


class _NotCatalogError(InputError):
    """An array element that is not what the format puts there (caught in this module: the
    catalog is a hint, and one that is not a catalog is no hint)."""


@dataclass(frozen=True, slots=True)
class CatalogFile:
    """A catalog's ``segments`` and ``problems`` arrays, still undecoded."""

    segments: msgspec.Raw
    problems: msgspec.Raw

    def rows(
        self,
        row_type: type[R],
        keep: Callable[[R], bool] | None = None,
        *,
        limit: int | None = None,
    ) -> list[R] | None:
        """The rows ``keep`` accepts (all without it), each decoded as ``row_type`` (a
        dataclass or msgspec Struct); None when an element is not such a row, or when more
        than ``limit`` rows are kept."""
        decoder = msgspec.json.Decoder(row_type)
        kept: list[R] = []
        try:
            for row in _elements(memoryview(self.segments), lambda a, p: _row_at(a, p, decoder)):
                if keep is None or keep(row):
                    kept.append(row)
                    if limit is not None and len(kept) > limit:
                        return None
        except _NotCatalogError:
            return None
        return kept

    def lists_no_problem(self) -> bool:
        """Whether the catalog's ``problems`` is an empty array."""
        return _EMPTY.match(memoryview(self.problems)) is not None

    def problems_listed(self, limit: int) -> list[str] | None:
        """The first ``limit`` problems the catalog lists (the rest are not read); None when
        one of them is not a string."""
        decoder = msgspec.json.Decoder(str)
        listed: list[str] = []
        try:
            for problem in _elements(
                memoryview(self.problems), lambda a, p: _string_at(a, p, decoder)
            ):
                if len(listed) == limit:
                    break
                listed.append(problem)
        except _NotCatalogError:
            return None
        return listed


def read_catalog_file(root: Path) -> CatalogFile | None:
    """``root``'s catalog, or None when it has none or one of another format; one that cannot
    be read (a link, a FIFO, over the side-file bound, not a catalog's JSON): ``LogReadError``.
    Its rows are checked as they are read (``CatalogFile.rows``)."""
    data = read_side_file(root / CATALOG_NAME)
    if data is None:
        return None
    path = root / CATALOG_NAME
    try:
        top = msgspec.json.decode(data, type=_Top)
    except msgspec.ValidationError as err:
        raise LogReadError(str(path), f"not a TRACE catalog ({err})") from err
    except msgspec.DecodeError as err:
        raise LogReadError(str(path), f"not JSON ({err})") from err
    except RecursionError as err:  # msgspec bounds nesting by the interpreter's depth
        raise LogLimitError(str(path), "nests too deep to read") from err
    if top.format != CATALOG_FORMAT:
        return None
    return CatalogFile(top.segments, top.problems)


def _elements(
    array: memoryview, element_at: Callable[[memoryview, int], tuple[R, int]]
) -> Iterator[R]:
    """The elements of a JSON array one at a time, each read by ``element_at`` (the value
    at a position, and where it ends); ``_NotCatalogError`` where the array holds anything else."""
    opened = _OPEN.match(array)
    if opened is None:
        raise _NotCatalogError
    pos = opened.end()
    if pos < len(array) and array[pos] == ord("]"):
        return
    while True:
        value, end = element_at(array, pos)
        yield value
        after = _AFTER.match(array, end)
        if after is None:
            raise _NotCatalogError
        if after.group(1):
            return
        pos = after.end()


def _row_at(array: memoryview, pos: int, decoder: msgspec.json.Decoder[R]) -> tuple[R, int]:
    """The flat object at ``pos`` and where it ends. The first brace after ``pos`` ends it
    unless that brace is inside a string: then the bytes before it end in an open string and
    are not JSON, and the exact (slower) match finds the end."""
    brace = _BRACE.search(array, pos)
    if brace is not None:
        try:
            return decoder.decode(array[pos : brace.end()]), brace.end()
        except msgspec.DecodeError:
            pass  # a brace in a string, or not a row: the exact match tells
    exact = _FLAT_OBJECT.match(array, pos)
    if exact is None:
        raise _NotCatalogError
    try:
        return decoder.decode(array[pos : exact.end()]), exact.end()
    except msgspec.DecodeError as err:
        raise _NotCatalogError from err


def _string_at(array: memoryview, pos: int, decoder: msgspec.json.Decoder[str]) -> tuple[str, int]:
    found = _STRING.match(array, pos)
    if found is None:
        raise _NotCatalogError
    return decoder.decode(array[pos : found.end()]), found.end()
