"""What the per-segment check gathers in one pass over a segment's sealed cycles, for the
link, numbering, reorder and checkpoint checks that read it afterwards.

Seal digests are kept as 64-bit prefixes (``digest_prefix``) in arrays: a log of millions of
cycles is held in a few bytes per cycle, and a link is compared in full only where it matters.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass, field

__all__ = ["AbsentRun", "Anchor", "ChainTail", "SealScan", "digest_prefix"]


@dataclass(slots=True)
class ChainTail:
    """Where a segment's chain ends: the next segment's first seal must name ``digest``."""

    digest: str
    cycle: int
    t_ns: int


@dataclass(slots=True)
class Anchor:
    """The last cycle a matching checkpoint vouches for."""

    cycle: int
    t_ns: int


@dataclass(slots=True)
class AbsentRun:
    """Consecutive citing cycles whose refs name messages a given recording does not hold."""

    recording: str
    first: tuple[int, int]  # (cycle, t)
    last: tuple[int, int]
    refs: int
    detail: str  # the first one


@dataclass(slots=True)
class SealScan:
    """Per sealed cycle, in reading order: number, time, digest prefixes, link check."""

    num: array[int] = field(default_factory=lambda: array("q"))
    t: array[int] = field(default_factory=lambda: array("q"))
    dig: array[int] = field(default_factory=lambda: array("Q"))
    prev: array[int] = field(default_factory=lambda: array("Q"))
    dropped: array[int] = field(default_factory=lambda: array("q"))
    link_ok: bytearray = field(default_factory=bytearray)
    last_digest: str | None = None
    heads: dict[int, list[str]] = field(default_factory=dict)
    unsealed: list[tuple[int, int, int]] = field(default_factory=list)  # (position, cycle, t)
    summarised: list[int] = field(default_factory=list)  # positions
    bad_positions: set[int] = field(default_factory=set)
    uncited: int = 0  # sensor readings no evidence ref with a digest names
    external_ok: int = 0  # evidence refs into external recordings that resolved and match
    external_unresolved: dict[str, int] = field(default_factory=dict)  # recording -> refs
    damaged: list[tuple[int, int, int]] = field(default_factory=list)
    """Cycle ranges lost in damaged chunks: (first, last, sealed cycles lost)."""
    backsteps: list[tuple[int, int, int, int]] = field(default_factory=list)
    """Where time went backwards: (cycle, t, the cycle before, its t)."""
    absent_open: dict[str, AbsentRun] = field(default_factory=dict)  # recording -> open run
    absent_runs: list[AbsentRun] = field(default_factory=list)


def digest_prefix(hex_digest: str) -> int:
    """The first 64 bits of a hex digest (0 for one that is not hex)."""
    try:
        return int(hex_digest[:16], 16)
    except ValueError:
        return 0
