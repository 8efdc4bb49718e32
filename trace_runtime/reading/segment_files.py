"""Which files make up a log: the one owner of segment discovery. A file is itself; below a
folder, every regular ``*.mcap`` file that is not a write in progress, known by its name
(``segment_names``) without being opened."""

from __future__ import annotations

import logging
import stat
from pathlib import Path

from trace_runtime.boundary import file_kind, tier_folder
from trace_runtime.errors import (
    LogReadError,
)
from trace_runtime.segment_names import parse_segment_name
from trace_runtime.session import TIERS

log = logging.getLogger("trace_runtime")


PARTIAL_MARK = ".partial"
"""File names holding this are writes in progress (compaction), never read as segments."""


BAG_METADATA = "metadata.yaml"
"""What marks a folder as a rosbag2 bag (a recording), whose MCAP files are not segments."""


def find_segment_files(path: Path) -> list[Path]:
    """Segment files of a log: the file itself, or every ``*.mcap`` below a directory
    (writes in progress excluded).

    Below a directory only regular files count: a link (to a file elsewhere, or a tier folder
    that is one: ``boundary.tier_folder`` refuses it) would let the log reach outside its
    folder, and a FIFO would block the reader, so each is skipped with a warning. The files
    of a rosbag2 bag kept in the folder (beside its ``metadata.yaml``: a robot's recording,
    profile 1.4) are not segments and are left to the recordings, without a word."""
    if not path.is_dir():
        return [path]
    for tier in TIERS:
        tier_folder(path, tier)
    files: list[Path] = []
    bags: dict[Path, bool] = {}
    for candidate in sorted(path.rglob("*.mcap")):
        if PARTIAL_MARK in candidate.name:
            continue
        folder = candidate.parent
        if folder not in bags:  # one stat a folder, not one a file
            bags[folder] = folder != path and (folder / BAG_METADATA).is_file()
        if bags[folder]:
            continue
        try:
            mode = candidate.lstat().st_mode
        except OSError:
            continue  # removed while we looked
        if stat.S_ISREG(mode):
            files.append(candidate)
        elif not stat.S_ISDIR(mode):
            log.warning("%s: %s, not a segment file; skipped", candidate, file_kind(mode))
    return files


def robot_segment_files(root: Path, robot_id: str) -> dict[int, list[Path]]:
    """``robot_id``'s segment files among a log root's (``find_segment_files``), by segment
    number, known by their names (``parse_segment_name``): nothing is opened."""
    return segment_files_by_robot(root).get(robot_id, {})


def segment_files_by_robot(root: Path) -> dict[str, dict[int, list[Path]]]:
    """Every robot's segment files among a log root's, by robot (in order of name), then
    by segment number, known by their names: nothing is opened."""
    found: dict[str, dict[int, list[Path]]] = {}
    for path in find_segment_files(root):
        parsed = parse_segment_name(path.name)
        if parsed is not None:
            found.setdefault(parsed[0], {}).setdefault(parsed[1], []).append(path)
    return dict(sorted(found.items()))


def files_of(path: Path) -> list[Path]:
    """The segment files a path names; a missing path or an empty directory is an error."""
    if not path.exists():
        raise LogReadError(str(path), "no such file or directory")
    files = find_segment_files(path)
    if not files:
        raise LogReadError(str(path), "directory holds no .mcap segments")
    return files
