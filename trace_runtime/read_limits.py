"""The bounds on what one MCAP file may make the reader do (``ReadLimits``).

An investigator opens files an attacker may have prepared, so every read the byte layer makes
is bounded by these: a chunk's decompressed size, the records it may hold for its compressed
size, a record's length. The reader, the recordings check and ``doctor`` take the same limits.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DEFAULT_LIMITS", "ReadLimits"]


@dataclass(frozen=True, slots=True)
class ReadLimits:
    """Bounds on what one file may make the reader do, so that reading costs about what an
    honest file of the same size would (within a constant factor), never a bomb's worth.

    The defaults are far above what an honest log needs: a TRACE chunk is a few MB at most
    (a camera frame a few tens of MB); zstd shrinks TRACE chunks about 4-16x and an honest
    chunk holds about 0.03 records per compressed byte (measured on simulator logs)."""

    max_chunk_bytes: int = 512 << 20
    """A chunk's decompressed size, as declared and as really produced, whatever its
    compressed size. (A stock MCAP writer cutting chunks by size writes chunks of its chunk
    size or of its largest message; tools re-chunk at up to a few hundred MB.)"""
    max_inflation: int = 1024
    """A chunk may declare at most this many times its compressed size (plus
    ``small_chunk_bytes``). Zeros compress ~30,000:1; without this bound an 80 KB file of
    40 chunks would make the reader inflate 2.5 GB."""
    small_chunk_bytes: int = 64 << 10
    """What any chunk may inflate to, whatever its compressed size."""
    records_per_compressed_byte: int = 1
    """Records a chunk may hold per byte of its compressed data (plus ``min_chunk_records``).
    Honest chunks hold well under one: every message carries a time and sequence that do not
    compress to nothing. A flood of empty messages that inflates from a few KB is refused."""
    min_chunk_records: int = 16
    """What any chunk may hold; small, so that a flood spread over many tiny chunks is
    bounded by the file's size too (about 1.3 records per file byte at worst)."""
    max_record_bytes: int = 1 << 32
    """A record in the file (outside chunks)."""

    def __post_init__(self) -> None:
        for name in (
            "max_chunk_bytes",
            "max_inflation",
            "small_chunk_bytes",
            "records_per_compressed_byte",
            "min_chunk_records",
        ):
            if getattr(self, name) <= 0:
                raise ValueError(f"ReadLimits.{name} must be positive")

    def chunk_bytes(self, compressed: int) -> int:
        """The most a chunk of ``compressed`` bytes may inflate to."""
        return min(self.max_chunk_bytes, self.small_chunk_bytes + self.max_inflation * compressed)

    def chunk_records(self, compressed: int) -> int:
        """The most records a chunk of ``compressed`` bytes may hold."""
        return self.min_chunk_records + self.records_per_compressed_byte * compressed


DEFAULT_LIMITS = ReadLimits()
