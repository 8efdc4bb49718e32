"""The index folder's own files: its manifest, its Parquet files, its lock.

An index folder travels like a log root (copied, synced, unpacked), so nothing in it is
trusted beyond what the folder itself shows (``trace_runtime.boundary``):

- ``index.json`` is read bounded in size and depth; a name it lists is used only when it is
  the index's own naming (``<table>/robot=<id>/day=<date>/<file>.parquet``) inside the folder,
  through no link. The query's confinement is made of such files, never of other names.
- The index writes a file aside under a fresh name and renames it into place, and deletes
  only files of its own naming inside the folder that are regular files.
- One ``index`` run at a time holds the folder's lock (``.index.lock``).
- A folder a run left without a manifest (killed, or a full disk) holds nothing but the
  index's own files: the next run recognises it and rebuilds it in place.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

from trace_audit.fleet.tables import INDEX_FORMAT, INDEX_VERSION, TABLES
from trace_runtime.boundary import (
    create_aside,
    folder_lock,
    read_side_json,
    remove_own_file,
    storage_error,
    write_atomic,
)
from trace_runtime.errors import LogReadError, StorageError, UnsafePathError, UsageError

__all__ = [
    "LOCK",
    "MANIFEST",
    "check_target",
    "discard_unlisted",
    "index_lock",
    "listed_files",
    "load_manifest",
    "own_file",
    "remove_own",
    "write_manifest",
    "write_table_file",
]

MANIFEST = "index.json"
LOCK = ".index.lock"
_OWN_NAME = re.compile(
    rf"^(?:{'|'.join(TABLES)})/robot=[A-Za-z0-9._-]+/day=(?:[0-9-]+|run-[0-9]+)/"
    r"[A-Za-z0-9._-]+\.parquet$"
)
"""The names the index gives its Parquet files (``index._segment_files``)."""


def load_manifest(index: str | Path) -> dict[str, Any] | None:
    """The index's manifest, or None when the folder holds no index of this version.

    Bounded and never followed through a link (``boundary.read_side_json``): a manifest
    that is a FIFO, a link, too large or too deep is refused with one line."""
    body = read_side_json(Path(index) / MANIFEST)
    if not isinstance(body, dict) or body.get("format") != INDEX_FORMAT:
        return None
    if body.get("version") != INDEX_VERSION:
        return None
    return body


def own_file(index: Path, rel: str) -> Path | None:
    """``index/rel`` when ``rel`` is a name of the index's own inside the folder, else None.

    The naming already keeps it inside (no ``..``, not absolute); what is left to refuse is
    a link on the way. A folder or file that is missing is still ours: a user who deleted
    one gets it indexed again, not a refusal."""
    if not isinstance(rel, str) or not _OWN_NAME.match(rel):
        return None
    path = index
    parts = rel.split("/")
    for depth, part in enumerate(parts):
        path = path / part
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            return index / rel  # nothing below a missing folder can be a link
        except OSError:
            return None
        last = depth == len(parts) - 1
        if stat.S_ISLNK(mode) or (not last and not stat.S_ISDIR(mode)):
            return None
    return path


def listed_files(index: Path, manifest: dict[str, Any]) -> list[str]:
    """The index's own Parquet files a manifest names (relative, sorted); ``LogReadError``
    when it names anything else (a path outside, a link): such a manifest is not ours."""
    entries = manifest.get("segments")
    if not isinstance(entries, dict):
        return []
    names: set[str] = set()
    for entry in entries.values():
        for rel in (entry.get("files") or ()) if isinstance(entry, dict) else ():
            if own_file(index, rel) is None:
                raise UnsafePathError(
                    str(index / MANIFEST),
                    f"names {str(rel)[:200]!r}, not a file of the index's own inside it; refused",
                )
            names.add(rel)
    return sorted(names)


def check_target(out: Path) -> dict[str, Any] | None:
    """The manifest to update, None for a new index; refuses a folder that is not ours, and
    a manifest that cannot be read (nothing in the folder is touched then).

    A folder without a manifest that holds only the index's own files (a run killed or
    stopped by a full disk) is ours: it is rebuilt, its files replaced or removed."""
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise UsageError(f"{out}: exists and is not a directory")
    if out.is_dir() and not os.access(out, os.W_OK):
        # Whatever the folder holds, a run needs to write there (its lock at least): what
        # the user can act on is the write, not whether the folder looks like an index.
        raise StorageError(str(out), "the folder is not writable (read-only or no permission)")
    try:
        body = read_side_json(out / MANIFEST)
    except LogReadError as err:
        raise LogReadError(
            err.path, f"{err.reason}; nothing changed (rebuild into a new directory)"
        ) from err
    if body is not None:
        if not isinstance(body, dict) or body.get("format") != INDEX_FORMAT:
            raise LogReadError(
                str(out / MANIFEST),
                "not a fleet index manifest; nothing changed (give a new directory)",
            )
        stale = listed_files(out, body)
        if body.get("version") != INDEX_VERSION:
            # Another version of our own index: its files are rebuilt in place; anything
            # else in the directory is left alone.
            return {"segments": {}, "stale_files": stale}
        return body
    if not out.is_dir():
        return None
    leftovers = _half_built(out)
    if leftovers is None:
        raise UsageError(f"{out}: not empty and not a fleet index; give a new directory")
    return {"segments": {}, "stale_files": leftovers} if leftovers else None


def _half_built(out: Path) -> list[str] | None:
    """The Parquet files of a folder that holds nothing but the index's own files and
    folders (and its lock and partial files); None when anything else is there."""
    found: list[str] = []
    with os.scandir(out) as tops:
        entries = list(tops)
    for top in entries:
        if top.name == LOCK or _partial_of(top.name):
            continue
        if top.name not in TABLES or not top.is_dir(follow_symlinks=False):
            return None
        for dirpath, dirnames, filenames in os.walk(top.path):
            here = Path(dirpath).relative_to(out).as_posix()
            for name in filenames:
                rel = f"{here}/{name}"
                if _partial_of(name):
                    continue
                if own_file(out, rel) is None or not os.path.isfile(out / rel):
                    return None
                found.append(rel)
            if any(os.path.islink(os.path.join(dirpath, d)) for d in dirnames):
                return None
    return sorted(found)


def _partial_of(name: str) -> bool:
    """A partial file of ``boundary.create_aside``'s naming."""
    return name.startswith(".") and name.endswith(".partial")


@contextlib.contextmanager
def index_lock(out: Path) -> Iterator[None]:
    """One ``index`` run per folder at a time; a second is refused with one line. The lock
    file goes when the run ends, however it ends."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise storage_error(out, err) from err
    held = f"{out}: another index run is writing this index"
    with folder_lock(out / LOCK, held=held, remove=True):
        yield


def discard_unlisted(out: Path) -> None:
    """Delete the index's own files that the manifest now in ``out`` does not name (all of
    them when there is none), and the folders left empty: what a run stopped by a full
    disk wrote is not left for anyone to take as indexed. Run with the lock held."""
    try:
        body = read_side_json(out / MANIFEST)
    except LogReadError:
        return  # a manifest we cannot read is not ours to judge by: touch nothing
    listed = set(listed_files(out, body)) if isinstance(body, dict) else set()
    for table in TABLES:
        top = out / table
        if top.is_symlink() or not top.is_dir():
            continue
        for dirpath, _, filenames in os.walk(top, topdown=False):
            for name in filenames:
                rel = (Path(dirpath) / name).relative_to(out).as_posix()
                if rel not in listed:
                    remove_own(out, rel)
            with contextlib.suppress(OSError):
                os.rmdir(dirpath)  # only when empty: a folder still holding files stays


def write_table_file(out: Path, rel: str, write: Callable[[BinaryIO], object]) -> None:
    """Write Parquet file ``out/rel`` aside through ``write(file)`` and rename it into place;
    its folder is made inside ``out`` and never reached through a link."""
    target = out / rel
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise storage_error(target.parent, err) from err
    if own_file(out, rel) is None:
        raise UnsafePathError(str(target), "is reached through a link or leads outside; refused")
    tmp, file = create_aside(target)
    try:
        try:
            with file:
                write(file)
            os.replace(tmp, target)
        except OSError as err:  # pyarrow's IO errors are OSErrors (a full disk: ENOSPC)
            raise storage_error(target, err) from err
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()  # our own, made just now under a fresh name
        raise


def remove_own(out: Path, rel: str) -> None:
    """Delete ``out/rel`` if it is one of the index's own files (named so, a regular file
    inside the folder); anything else is left where it is."""
    path = own_file(out, rel)
    if path is not None:
        remove_own_file(path)


def write_manifest(
    out: Path, segments: dict[str, Any], settings: dict[str, Any], digests: dict[str, Any]
) -> None:
    """Replace the manifest (written aside, fsynced, renamed)."""
    body = {
        "format": INDEX_FORMAT,
        "version": INDEX_VERSION,
        "config": settings,
        "segments": dict(sorted(segments.items())),
        "digests": digests,
    }
    write_atomic(out / MANIFEST, (json.dumps(body, indent=1) + "\n").encode())
