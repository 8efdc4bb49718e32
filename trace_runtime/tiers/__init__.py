"""Storage tiers of a log root: warm summaries, the lossless cold codec, catalog, compaction.

The reader imports the tier codecs (``tiers.warm``, ``tiers.cold``) directly; compaction
imports the reader. Names here are imported on first use, so importing one codec does not
pull compaction (and the reader) in behind it: the imports stay one way.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_runtime.lazy import lazy_exports

_EXPORTS = {
    "CATALOG_NAME": "trace_runtime.tiers.catalog",
    "Catalog": "trace_runtime.tiers.catalog",
    "CatalogEntry": "trace_runtime.tiers.catalog",
    "load_catalog": "trace_runtime.tiers.catalog",
    "refresh_catalog": "trace_runtime.tiers.catalog",
    "CODEC": "trace_runtime.tiers.cold",
    "BlockEncoder": "trace_runtime.tiers.cold",
    "assemble_cold": "trace_runtime.tiers.cold",
    "decode_block": "trace_runtime.tiers.cold",
    "iter_decoded": "trace_runtime.tiers.cold",
    "DEFAULT_OLDER_THAN_NS": "trace_runtime.tiers.compaction",
    "DEFAULT_RETENTION_NS": "trace_runtime.tiers.compaction",
    "ColdOptions": "trace_runtime.tiers.compaction",
    "CompactionReport": "trace_runtime.tiers.compaction",
    "Leftover": "trace_runtime.tiers.compaction",
    "Progress": "trace_runtime.tiers.compaction",
    "RetentionResult": "trace_runtime.tiers.compaction",
    "SegmentResult": "trace_runtime.tiers.compaction",
    "chain_problems": "trace_runtime.tiers.compaction",
    "compact": "trace_runtime.tiers.compaction",
    "parse_duration": "trace_runtime.tiers.compaction",
    "recover": "trace_runtime.tiers.compaction",
    "verify_replacement": "trace_runtime.tiers.compaction",
    "WarmPolicy": "trace_runtime.tiers.warm",
    "assemble_warm": "trace_runtime.tiers.warm",
    "summarize": "trace_runtime.tiers.warm",
}

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

if TYPE_CHECKING:
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


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, __all__)
