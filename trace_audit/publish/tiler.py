"""A robot's tree cut into C2SP tiles as its entries stream by, in bounded memory.

``TileBuilder`` keeps, per level, only the hashes of the one tile not yet full (at most 256
each) and the entries of the level-0 bundle not yet full: a 24 h log is cut with a few
hundred KB, whatever its size. Each full tile is handed out once, when its last hash
arrives; the partial tiles of the tree as it stands are asked for at the sizes that need
them (those a checkpoint states). The root comes from a ``CompactRange`` kept beside.
"""

from __future__ import annotations

from dataclasses import dataclass

from trace_runtime.tlog.merkle import CompactRange, leaf_hash, root_of
from trace_runtime.tlog.tiles import TILE_WIDTH, encode_bundle, entries_path, tile_path

__all__ = ["TileBuilder", "TileFile"]


@dataclass(frozen=True, slots=True)
class TileFile:
    """One file of the published tree: its path under the robot's folder and its bytes."""

    path: str
    data: bytes


class TileBuilder:
    """Leaves in, tiles out (see the module doc)."""

    def __init__(self) -> None:
        self._levels: list[list[bytes]] = [[]]
        self._counts: list[int] = [0]  # hashes ever appended at each tile level
        self._entries: list[bytes] = []
        self._compact = CompactRange()

    @property
    def size(self) -> int:
        return self._compact.size

    def root(self) -> bytes:
        return self._compact.root()

    def append(self, entry: bytes) -> list[TileFile]:
        """Add one entry (a seal's stored bytes); the files it completes, if any."""
        h = leaf_hash(entry)
        self._compact.append(h)
        self._entries.append(entry)
        done: list[TileFile] = []
        if len(self._entries) == TILE_WIDTH:
            n = self._counts[0] // TILE_WIDTH
            done.append(TileFile(entries_path(n), encode_bundle(self._entries)))
            self._entries = []
        level = 0
        while True:
            hashes = self._levels[level]
            hashes.append(h)
            self._counts[level] += 1
            if len(hashes) < TILE_WIDTH:
                return done
            n = self._counts[level] // TILE_WIDTH - 1
            done.append(TileFile(tile_path(level, n), b"".join(hashes)))
            h = root_of(hashes)  # a full tile's root is one hash of the level above
            self._levels[level] = []
            level += 1
            if level == len(self._levels):
                self._levels.append([])
                self._counts.append(0)

    def partial_tiles(self) -> list[TileFile]:
        """The partial hash tiles of the tree as it stands (none at a level whose count is a
        multiple of 256: empty tiles are never served)."""
        return [
            TileFile(tile_path(level, count // TILE_WIDTH, len(hashes)), b"".join(hashes))
            for level, (hashes, count) in enumerate(zip(self._levels, self._counts, strict=True))
            if hashes
        ]

    def partial_bundle(self) -> TileFile | None:
        """The partial entry bundle of the tree as it stands, if it has one."""
        if not self._entries:
            return None
        n = self._counts[0] // TILE_WIDTH
        return TileFile(entries_path(n, len(self._entries)), encode_bundle(self._entries))
