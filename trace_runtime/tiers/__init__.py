"""Storage tiers of a log root, above verification: the catalog, and compaction into the warm
or cold tier with its recovery and the cold tier's retention.

``catalog`` indexes the segment files; ``plan`` chooses what moves; ``write`` writes and checks
a segment's copy; ``replace`` swaps it in; ``workers`` fans segments out to processes;
``recover`` settles what a killed run left; ``retention`` retires old verified cold segments;
``copies`` says whether one copy stands for another; ``durations`` reads ``24h``-style
durations; ``compaction`` is the entry point. The tier formats themselves (warm summaries,
the cold codec) sit below the reader, in ``trace_runtime.tier_formats``.
"""

from __future__ import annotations

from trace_runtime.reading.catalog_rows import CATALOG_NAME
from trace_runtime.tier_formats.cold import (
    CODEC,
    BlockEncoder,
    assemble_cold,
    decode_block,
    iter_decoded,
)
from trace_runtime.tier_formats.warm import WarmPolicy, assemble_warm, summarize
from trace_runtime.tiers.catalog import (
    Catalog,
    CatalogEntry,
    load_catalog,
    refresh_catalog,
)
from trace_runtime.tiers.compaction import DEFAULT_OLDER_THAN_NS, DEFAULT_RETENTION_NS, compact
from trace_runtime.tiers.copies import chain_problems, verify_replacement
from trace_runtime.tiers.durations import parse_duration
from trace_runtime.tiers.recover import recover
from trace_runtime.tiers.report import (
    ColdOptions,
    CompactionReport,
    Leftover,
    Progress,
    RetentionResult,
    SegmentResult,
)

__all__ = [
    "CATALOG_NAME",
    "CODEC",
    "DEFAULT_OLDER_THAN_NS",
    "DEFAULT_RETENTION_NS",
    "BlockEncoder",
    "Catalog",
    "CatalogEntry",
    "ColdOptions",
    "CompactionReport",
    "Leftover",
    "Progress",
    "RetentionResult",
    "SegmentResult",
    "WarmPolicy",
    "assemble_cold",
    "assemble_warm",
    "chain_problems",
    "compact",
    "decode_block",
    "iter_decoded",
    "load_catalog",
    "parse_duration",
    "recover",
    "refresh_catalog",
    "summarize",
    "verify_replacement",
]
