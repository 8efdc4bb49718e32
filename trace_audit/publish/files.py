"""A robot's published folder: immutable tiles written once, the checkpoint replaced.

A static web server may serve the folder while ``publish`` runs, so no reader ever sees
half a file: every file is written beside its name (``boundary.create_aside``), fsynced,
then linked in under its name. A tile or bundle is immutable: a name already held is never
replaced; its bytes are compared instead, and a difference is a ``TileConflictError`` (the log
no longer holds the history published from it, or the folder was altered). New tiles are
*staged* (written aside) and linked in only when ``commit`` says a checkpoint vouches for
them, so a tree that turns out not to match its checkpoint leaves nothing published; a
staged file not committed is removed (``discard``): it is this run's own. What a run killed
before it could remove its own left beside a name is removed by the next run that enters
that folder (``_sweep``).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from trace_audit.publish.tiler import TileFile
from trace_runtime.boundary import (
    create_aside,
    fsync_dir,
    read_side_file,
    regular_file,
    remove_stale_asides,
    storage_error,
    write_atomic,
)
from trace_runtime.errors import InputError, StorageError, UnsafePathError
from trace_runtime.tlog.tiles import MAX_ENTRY_BYTES, TILE_WIDTH

__all__ = ["MAX_TILE_FILE", "PublishedFolder", "TileConflictError", "make_top"]

MAX_TILE_FILE = TILE_WIDTH * (2 + MAX_ENTRY_BYTES)
"""The largest file of a published tree (a full bundle of the largest entries)."""


class TileConflictError(InputError):
    """A published tile or bundle whose bytes differ from the log's (``publish`` turns it
    into a problem of the robot, exit 1, before it could end the command)."""

    def __init__(self, path: str) -> None:
        super().__init__(path)
        self.path = path


class PublishedFolder:
    """The files of one robot's published tree (see the module doc)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.written = 0
        self.kept = 0
        self.removed = 0
        """Files a killed run left beside their names, removed (``_sweep``)."""
        self._staged: list[tuple[Path, Path]] = []
        self._made: set[Path] = set()
        self._seen: set[str] = set()  # this run's paths: a level-1 partial recurs per checkpoint
        self._dirty: set[Path] = set()  # folders whose new names ``sync`` makes durable

    def _path(self, relative: str) -> Path:
        path = self.folder / relative
        if path.parent not in self._made:
            _make_folders(self.folder, path.parent)
            self._made.add(path.parent)
            self._sweep(path.parent)
        return path

    def _sweep(self, folder: Path) -> None:
        """Remove what a killed run left in ``folder`` (a folder of this tree, entered
        once a run, which holds the output folder's lock): only files named as
        ``create_aside`` names them beside a name this tree holds, by a process that no
        longer runs; a file of any other name, a link or a folder is left alone."""
        self.removed += remove_stale_asides(folder, _tree_name)

    def stage(self, tile: TileFile) -> None:
        """Write ``tile`` aside when its name is free; compare it when the name is held."""
        if tile.path in self._seen:
            return
        self._seen.add(tile.path)
        path = self._path(tile.path)
        if self._held(path, tile):
            return
        tmp, f = create_aside(path)
        self._staged.append((tmp, path))
        try:
            with f:
                f.write(tile.data)
                f.flush()
                _datasync(f.fileno())  # its bytes are durable before its name points at them
        except OSError as err:
            raise storage_error(path, err) from err

    def _held(self, path: Path, tile: TileFile) -> bool:
        if not regular_file(path):
            return False
        if read_side_file(path, limit=MAX_TILE_FILE) != tile.data:
            raise TileConflictError(tile.path)
        self.kept += 1
        return True

    def commit(self) -> None:
        """Link every staged file in under its name (a name taken meanwhile is compared)."""
        staged = self._staged
        for i, (tmp, path) in enumerate(staged):
            self._staged = staged[i + 1 :]  # what ``discard`` removes should this one fail
            try:
                self._link(tmp, path)
            finally:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)  # our own, made this run under a name no one else holds
            self._dirty.add(path.parent)
        self._staged = []

    def sync(self) -> None:
        """Make every name linked in so far durable: once per robot, before its checkpoint
        is replaced (a name lost to a crash before then is written again by the next run;
        the checkpoint never names a tree whose tiles a crash could take away)."""
        for folder in sorted(self._dirty):
            fsync_dir(folder)
        self._dirty.clear()

    def _link(self, tmp: Path, path: Path) -> None:
        try:
            os.link(tmp, path, follow_symlinks=False)
        except FileExistsError:
            if read_side_file(path, limit=MAX_TILE_FILE) != read_side_file(tmp):
                raise TileConflictError(str(path.relative_to(self.folder))) from None
            self.kept += 1
            return
        except OSError as err:
            raise storage_error(path, err) from err
        self.written += 1

    def discard(self) -> None:
        """Remove every staged file not committed (each one this run's own)."""
        for tmp, _path in self._staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        self._staged = []

    def replace(self, relative: str, data: bytes) -> None:
        """Replace a mutable file (the checkpoint) atomically, unless it holds ``data``."""
        path = self._path(relative)
        if regular_file(path) and read_side_file(path, limit=MAX_TILE_FILE) == data:
            self.kept += 1
            return
        write_atomic(path, data)
        self.written += 1


def _tree_name(name: str) -> bool:
    """A name ``publish`` writes: ``checkpoint``, or a tile's (``000``-``999``, the index
    elements, or a partial tile's width ``1``-``255``)."""
    return name == "checkpoint" or (name.isascii() and name.isdigit() and len(name) <= 3)


def _datasync(fd: int) -> None:
    sync = getattr(os, "fdatasync", os.fsync)  # fdatasync: Linux; fsync elsewhere
    sync(fd)


def _make_folders(top: Path, folder: Path) -> None:
    """Create ``folder`` (under ``top``) and its parents; a link or file where a folder of
    the tree belongs is refused, never followed."""
    parts = folder.relative_to(top).parts
    path = top
    for part in parts:
        path = path / part
        try:
            os.mkdir(path)
            continue
        except FileExistsError:
            pass
        except OSError as err:
            raise storage_error(path, err) from err
        if path.is_symlink() or not path.is_dir():
            raise UnsafePathError(str(path), "it is not a folder of the published tree")


def make_top(folder: Path) -> None:
    """Create a robot's folder (its parent, the output folder, may be new too)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise StorageError(str(folder), err.strerror or str(err)) from err
    if folder.is_symlink():
        raise UnsafePathError(str(folder), "a robot's published folder is a symbolic link")
