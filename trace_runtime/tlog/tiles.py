"""C2SP tlog-tiles (c2sp.org/tlog-tiles): where a tree's tiles and entry bundles live, and
the bytes of an entry bundle.

A tile is 256 consecutive hashes at tree level ``8 * L``; the ``N``-th tile of level ``L``
holds the Merkle tree hashes of leaves ``[(N*256 + i) * 256**L, (N*256 + i + 1) * 256**L)``,
``i`` from 0. A tree of size ``s`` has ``s // 256**(L+1)`` full tiles at level ``L`` and
one partial tile of ``(s // 256**L) % 256`` hashes when that is not zero. Paths:
``tile/<L>/<N>[.p/<W>]`` and ``tile/entries/<N>[.p/<W>]``, ``N`` in zero-padded 3-digit
path elements, all but the last prefixed ``x`` (so a file system holds them as they are
served). An entry bundle is its entries, each prefixed with its length as a big-endian
uint16: an entry is at most 65,535 bytes.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from trace_runtime.errors import MerkleError

__all__ = [
    "MAX_ENTRY_BYTES",
    "TILE_HEIGHT",
    "TILE_WIDTH",
    "bundle_entries",
    "encode_bundle",
    "entries_path",
    "partial_widths",
    "tile_index_path",
    "tile_path",
]

TILE_HEIGHT = 8
TILE_WIDTH = 1 << TILE_HEIGHT
MAX_ENTRY_BYTES = 0xFFFF


def tile_index_path(n: int) -> str:
    """A tile index as C2SP spells it: ``1234067`` is ``x001/x234/067``."""
    if n < 0:
        raise MerkleError(f"a tile index is not negative, got {n}")
    groups = [f"{n % 1000:03d}"]
    n //= 1000
    while n:
        groups.append(f"x{n % 1000:03d}")
        n //= 1000
    return "/".join(reversed(groups))


def _suffix(width: int) -> str:
    if not 1 <= width <= TILE_WIDTH:
        raise MerkleError(f"a tile is 1 to {TILE_WIDTH} hashes wide, got {width}")
    return "" if width == TILE_WIDTH else f".p/{width}"


def tile_path(level: int, n: int, width: int = TILE_WIDTH) -> str:
    """The path of hash tile ``n`` of ``level`` (a partial one when ``width`` < 256)."""
    if not 0 <= level <= 63:
        raise MerkleError(f"a tile level is 0 to 63, got {level}")
    return f"tile/{level}/{tile_index_path(n)}{_suffix(width)}"


def entries_path(n: int, width: int = TILE_WIDTH) -> str:
    """The path of entry bundle ``n`` (a partial one when ``width`` < 256)."""
    return f"tile/entries/{tile_index_path(n)}{_suffix(width)}"


def partial_widths(size: int) -> Iterator[tuple[int, int, int]]:
    """``(level, n, width)`` of each partial tile of a tree of ``size`` leaves, level 0 up."""
    level, count = 0, size
    while count:
        width = count % TILE_WIDTH
        if width:
            yield level, count // TILE_WIDTH, width
        level, count = level + 1, count // TILE_WIDTH


def encode_bundle(entries: Sequence[bytes]) -> bytes:
    """An entry bundle: each entry after its big-endian uint16 length."""
    parts: list[bytes] = []
    for entry in entries:
        if len(entry) > MAX_ENTRY_BYTES:
            raise MerkleError(
                f"an entry of {len(entry):,} bytes does not fit an entry bundle "
                f"(at most {MAX_ENTRY_BYTES:,})"
            )
        parts.append(len(entry).to_bytes(2, "big"))
        parts.append(entry)
    return b"".join(parts)


def bundle_entries(data: bytes) -> list[bytes]:
    """The entries of a bundle; ``MerkleError`` when its lengths do not add up."""
    entries: list[bytes] = []
    at = 0
    while at < len(data):
        if at + 2 > len(data):
            raise MerkleError("an entry bundle ends inside a length prefix")
        length = int.from_bytes(data[at : at + 2], "big")
        at += 2
        if at + length > len(data):
            raise MerkleError("an entry bundle ends inside an entry")
        entries.append(data[at : at + length])
        at += length
    return entries
