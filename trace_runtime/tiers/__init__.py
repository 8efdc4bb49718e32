"""Storage tiers of a log root: warm summaries, the lossless cold codec, catalog, compaction.

Importing this package teaches the reader the ``warm`` and ``cold`` tiers (the reader
imports it by itself when it meets a segment of either tier).
"""

from __future__ import annotations

from trace_runtime.reader import register_assembler
from trace_runtime.tiers.catalog import (
    CATALOG_NAME,
    Catalog,
    CatalogEntry,
    load_catalog,
    refresh_catalog,
)
from trace_runtime.tiers.cold import (
    CODEC,
    BlockEncoder,
    assemble_cold,
    decode_block,
    iter_decoded,
    register_inner,
)
from trace_runtime.tiers.compaction import (
    DEFAULT_OLDER_THAN_NS,
    DEFAULT_RETENTION_NS,
    ColdOptions,
    CompactionReport,
    Leftover,
    Progress,
    RetentionResult,
    SegmentResult,
    chain_problems,
    compact,
    parse_duration,
    recover,
    verify_replacement,
)
from trace_runtime.tiers.warm import WarmPolicy, assemble_warm, summarize

register_assembler("warm", assemble_warm)
register_assembler("cold", assemble_cold)
register_inner("warm", assemble_warm)

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
