"""A published folder (``trace-audit publish --out DIR``) served read-only by the witness
(``witness serve --tiles DIR``): ``GET /tiles/<robot>/checkpoint`` and
``GET /tiles/<robot>/tile/...``, so one process is a robot fleet's witness and its tlog.

Only the names a published tree holds are served: the request path must be one of the
C2SP tlog-tiles grammar (a robot id, then ``checkpoint``, ``tile/<L>/<N>[.p/<W>]`` or
``tile/entries/<N>[.p/<W>]``, ``N`` in 3-digit elements), or it is not found, whatever DIR
holds; a path is never decoded, so ``%2e%2e`` is a name like any other and matches nothing.
The file is then read through ``boundary.confined`` (no folder of the way a link) and
``boundary.read_side_file`` (not through a link, a regular file, at most the largest tile):
nothing outside DIR, nothing but a published file, is ever read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from trace_audit.publish.files import MAX_TILE_FILE
from trace_runtime.boundary import confined, read_side_file
from trace_runtime.errors import LogReadError, UsageError

__all__ = ["PREFIX", "Served", "TileFolder"]

PREFIX = "/tiles/"
_ROBOT = r"[A-Za-z0-9][A-Za-z0-9_-]*(?:\.[A-Za-z0-9_-]+)*"
_INDEX = r"(?:x[0-9]{3}/)*[0-9]{3}"
_WIDTH = r"(?:\.p/(?:[1-9]|[1-9][0-9]|1[0-9]{2}|2[0-4][0-9]|25[0-5]))?"
_LEVEL = r"(?:[0-9]|[1-5][0-9]|6[0-3]|entries)"
_PATH = re.compile(rf"({_ROBOT})/(checkpoint|tile/{_LEVEL}/{_INDEX}{_WIDTH})")
_CACHE_TILE = "public, max-age=31536000, immutable"  # a tile's bytes never change
_CACHE_CHECKPOINT = "no-cache"  # replaced as the robot logs: asked again each time


@dataclass(frozen=True, slots=True)
class Served:
    """A published file's bytes and the headers it is served with."""

    body: bytes
    content_type: str
    cache_control: str


class TileFolder:
    """The folder ``publish`` writes into, read as the module doc says."""

    def __init__(self, folder: Path) -> None:
        if folder.is_symlink() or not folder.is_dir():
            raise UsageError(f"--tiles {folder}: not a folder (publish --out writes one)")
        self.folder = folder

    def get(self, path: str) -> Served | None:
        """The file a request path (after ``PREFIX``) names, or None: not found."""
        match = _PATH.fullmatch(path) if len(path) <= 300 else None
        if match is None:
            return None
        name = match.group(2)
        target = confined(self.folder, path)
        if target is None:
            return None
        try:
            data = read_side_file(target, limit=MAX_TILE_FILE)
        except LogReadError:  # a link, a FIFO, a folder or an oversized file: not served
            return None
        if data is None:
            return None
        if name == "checkpoint":
            return Served(data, "text/plain; charset=utf-8", _CACHE_CHECKPOINT)
        return Served(data, "application/octet-stream", _CACHE_TILE)
