"""The storage tiers' formats, below the reader: how warm and cold segments hold cycles.

``warm`` (flagged cycles in full, routine ones summarised), ``shapes`` (the structure of a
JSON message, compiled) and ``cold`` (the lossless columnar block codec). The reader reads
warm and cold chunks through the assemblers here; writing a tier, the catalog, recovery and
retention sit above verification, in ``trace_runtime.tiers``.
"""

from __future__ import annotations

from trace_runtime.tier_formats.cold import (
    CODEC,
    BlockCache,
    BlockEncoder,
    ColdAssembler,
    assemble_cold,
    decode_block,
    iter_decoded,
)
from trace_runtime.tier_formats.warm import (
    WarmAssembler,
    WarmPolicy,
    assemble_warm,
    summarize,
    warm_cycles,
)

__all__ = [
    "CODEC",
    "BlockCache",
    "BlockEncoder",
    "ColdAssembler",
    "WarmAssembler",
    "WarmPolicy",
    "assemble_cold",
    "assemble_warm",
    "decode_block",
    "iter_decoded",
    "summarize",
    "warm_cycles",
]
