"""``BlockCache``: what decoding blocks needs kept between blocks: the last few decoded
blocks, the compiled shapes their headers name, and a zstd decompressor for each thread.

python-zstandard forbids using one decompressor from two threads at once, so each thread
that decodes through a cache gets its own; the shapes are shared (compiling one costs
milliseconds) and the cache of blocks is guarded by a lock.

A block is bounded as the hot reader bounds a chunk (``ReadLimits.chunk_bytes`` of its
compressed size): the size its zstd frame declares (the encoder always writes it; a frame
without one is refused) is checked before anything is allocated, and zstd inflates the
frame into exactly that much. What the body then makes the decoder build is bounded by a
``BuildBudget``.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict

import zstandard

from trace_runtime.errors import ColdFormatError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.tier_formats.cold.decode import DecodedBlock, decode_body
from trace_runtime.tier_formats.cold.format import (
    MAGIC,
    BuildBudget,
    gc_paused,
    malformed_as_format_error,
)
from trace_runtime.tier_formats.cold.seek import PartialBlock
from trace_runtime.tier_formats.shapes import ShapeCache


class BlockCache:
    """The last few decoded blocks: an investigation asks about nearby times (a decision, the
    cycles before it, their sensor readings) and each ask reads the block again. Keyed by
    the block's digest, so the same bytes share an entry. Thread-safe; owned by an assembler
    (so it lives as long as whoever holds that assembler: a reader, a compaction) or by an
    encoder, which decodes each block it makes with its own shapes. ``size`` 0 keeps no
    blocks, only the shapes. ``limits`` bound what one block may make it do (the encoder
    checks its blocks within the same ones, so it never writes a block a reader refuses)."""

    def __init__(self, size: int = 4, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        if size < 0:
            raise ValueError("BlockCache size must not be negative")
        self.size = size
        self.limits = limits
        self.shapes = ShapeCache()
        self._blocks: OrderedDict[bytes, DecodedBlock | PartialBlock] = OrderedDict()
        self._lock = threading.Lock()
        self._per_thread = threading.local()

    def __len__(self) -> int:
        return len(self._blocks)

    def _decompressor(self) -> zstandard.ZstdDecompressor:
        found: zstandard.ZstdDecompressor | None = getattr(self._per_thread, "zstd", None)
        if found is None:
            found = self._per_thread.zstd = zstandard.ZstdDecompressor()
        return found

    def body(self, block: bytes) -> bytes:
        """The decompressed body of a block (every decode, whole or partial, starts here),
        never larger than the limits allow for the block's size."""
        if block[:4] != MAGIC:
            raise ColdFormatError("not a trace-cold-v1 block (bad magic)")
        frame = block[4:]
        most = self.limits.chunk_bytes(len(block))
        with malformed_as_format_error():
            declared = zstandard.frame_content_size(frame)
            if declared < 0:
                raise ColdFormatError("cold block does not declare its decompressed size")
            if declared > most:
                raise ColdFormatError(
                    f"cold block declares {declared} bytes decompressed from {len(block)}, "
                    f"over the limit of {most} bytes"
                )
            if declared == 0:
                raise ColdFormatError("cold block declares an empty body")
            # zstd allocates what the frame declares and fails a frame that holds more
            return self._decompressor().decompress(frame, max_output_size=declared)

    def budget(self) -> BuildBudget:
        """What one decode of a block may build within the cache's limits."""
        return BuildBudget.within(self.limits)

    def _get(self, key: bytes) -> DecodedBlock | PartialBlock | None:
        with self._lock:
            found = self._blocks.get(key)
            if found is not None:
                self._blocks.move_to_end(key)
            return found

    def _put(self, key: bytes, block: DecodedBlock | PartialBlock) -> None:
        with self._lock:
            self._blocks[key] = block
            while len(self._blocks) > self.size:
                self._blocks.popitem(last=False)

    def _decode(self, data: bytes) -> DecodedBlock:
        body = self.body(data)
        with malformed_as_format_error(), gc_paused():
            return decode_body(body, self.shapes, budget=self.budget())

    def decode(self, data: bytes) -> DecodedBlock:
        """Every message of the block ``data``, byte for byte, in order (plain ones left
        out); from the cache when it was decoded lately."""
        if self.size == 0:
            return self._decode(data)
        key = hashlib.sha256(data).digest()
        found = self._get(key)
        if isinstance(found, DecodedBlock):
            return found
        block = self._decode(data)
        self._put(key, block)
        return block

    def decode_checked(self, data: bytes, digests: list[str]) -> DecodedBlock:
        """``decode`` for the encoder's check, given the digests of the messages the block
        was made from: a digest reference is resolved from them instead of hashing the
        message it points at again. The check then compares every decoded message with its
        input, so when it passes each digest used was the digest of the decoded bytes too,
        and a plain decode gives the same result (when it fails, the block is not used).
        Never cached."""
        body = self.body(data)
        with malformed_as_format_error(), gc_paused():
            return decode_body(body, self.shapes, dict(enumerate(digests)), self.budget())

    def open(self, data: bytes) -> DecodedBlock | PartialBlock:
        """The block whole if it was decoded lately, else opened for a partial decode (kept,
        so a second seek into it reuses the columns and messages the first one built)."""
        key = hashlib.sha256(data).digest() if self.size else b""
        found = self._get(key) if self.size else None
        if found is not None:
            return found
        body = self.body(data)
        with malformed_as_format_error(), gc_paused():
            block = PartialBlock(body, self.shapes, self.budget())
        if self.size:
            self._put(key, block)
        return block

    def clear(self) -> None:
        """Forget the decoded blocks (the compiled shapes stay)."""
        with self._lock:
            self._blocks.clear()


def decode_block(block: bytes) -> DecodedBlock:
    """Decode one block on its own: every message byte for byte, in order (plain ones left
    out). A caller decoding many blocks keeps a ``BlockCache`` instead, to share shapes."""
    return BlockCache(0).decode(block)
