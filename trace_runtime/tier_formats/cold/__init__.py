"""The cold tier's format: a lossless columnar codec for blocks of cycles, stored inside MCAP.

``format`` holds the constants and the error; ``columns`` the byte coding of streams and
columns; ``sensors`` the rule a seal's sensors digest is derived by; ``encode`` the
encoder; ``decode`` a whole-block decode; ``seek`` a partial one (one cycle); ``cache`` the
``BlockCache`` that owns what decoding keeps between blocks (decoded blocks, compiled
shapes, a decompressor per thread); ``blocks`` the block stream of a segment and the
reader's assembler.
"""

from __future__ import annotations

from trace_runtime.tier_formats.cold.blocks import (
    ColdAssembler,
    assemble_cold,
    index_entry,
    iter_blocks,
    iter_decoded,
    merge_plain,
    split_plain,
)
from trace_runtime.tier_formats.cold.cache import BlockCache, decode_block
from trace_runtime.tier_formats.cold.decode import DecodedBlock
from trace_runtime.tier_formats.cold.encode import SEAL_ANCHOR_CYCLES, BlockEncoder
from trace_runtime.tier_formats.cold.format import (
    BLOCK_SCHEMA,
    BLOCK_TOPIC,
    CODEC,
    DEFAULT_BLOCK_CYCLES,
    DEFAULT_LEVEL,
    INDEX_SCHEMA,
    INDEX_TOPIC,
    PLAIN_TOPICS,
    gc_paused,
)
from trace_runtime.tier_formats.cold.seek import PartialBlock

__all__ = [
    "BLOCK_SCHEMA",
    "BLOCK_TOPIC",
    "CODEC",
    "DEFAULT_BLOCK_CYCLES",
    "DEFAULT_LEVEL",
    "INDEX_SCHEMA",
    "INDEX_TOPIC",
    "PLAIN_TOPICS",
    "SEAL_ANCHOR_CYCLES",
    "BlockCache",
    "BlockEncoder",
    "ColdAssembler",
    "DecodedBlock",
    "PartialBlock",
    "assemble_cold",
    "decode_block",
    "gc_paused",
    "index_entry",
    "iter_blocks",
    "iter_decoded",
    "merge_plain",
    "split_plain",
]
