"""The catalog of a log root: rebuilt from the files, unreadable files listed as problems."""

from __future__ import annotations

from pathlib import Path

from tests.trace_runtime.tier_logs import make_root
from trace_runtime import open_log
from trace_runtime.chain import digest
from trace_runtime.records import (
    GENESIS,
    TOPIC_SEAL,
)
from trace_runtime.tiers import (
    CATALOG_NAME,
    compact,
    load_catalog,
    refresh_catalog,
)

# --- catalog -----------------------------------------------------------------------------------


def test_catalog_is_rebuilt_from_the_files(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=30, segments=3)
    assert load_catalog(root) is None
    catalog = refresh_catalog(root)
    assert (root / CATALOG_NAME).exists()
    assert [(e.tier, e.segment) for e in catalog.entries] == [("hot", 0), ("hot", 1), ("hot", 2)]
    log = open_log(root)
    for entry, segment in zip(catalog.entries, log.segments, strict=True):
        cycles = [c for c in segment.iter_cycles() if c.sealed]
        assert entry.cycles == len(cycles)
        assert (entry.first_cycle, entry.last_cycle) == (cycles[0].cycle, cycles[-1].cycle)
        assert entry.first_seal == digest(cycles[0].payloads[TOPIC_SEAL])
        assert entry.last_seal == digest(cycles[-1].payloads[TOPIC_SEAL])
        assert entry.prev_seal == segment.session.prev_seal
        assert (entry.start_ns, entry.end_ns) == (segment.info.start_ns, segment.info.end_ns)
        assert entry.bytes == segment.path.stat().st_size
    # the chain runs through the catalog: each segment starts where the previous one ended
    assert catalog.entries[0].prev_seal == GENESIS
    assert catalog.entries[1].prev_seal == catalog.entries[0].last_seal
    # compacting changes the rows, not the facts; a lost catalog comes back the same
    compact(root, "cold", older_than_ns=0, sources=["hot"])
    cold = load_catalog(root)
    assert cold is not None
    assert [e.tier for e in cold.entries] == ["cold"] * 3
    for before, after in zip(catalog.entries, cold.entries, strict=True):
        assert (after.first_seal, after.last_seal, after.cycles, after.start_ns, after.end_ns) == (
            before.first_seal,
            before.last_seal,
            before.cycles,
            before.start_ns,
            before.end_ns,
        )
    (root / CATALOG_NAME).unlink()
    rebuilt = refresh_catalog(root)
    assert [(e.path, e.sha256) for e in rebuilt.entries] == [
        (e.path, e.sha256) for e in cold.entries
    ]
    assert not list(root.glob("*.partial"))


def test_catalog_lists_unreadable_files_as_problems(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=10)
    (root / "hot" / "junk_000001.mcap").write_bytes(b"not an mcap file")
    catalog = refresh_catalog(root, write=False)
    assert len(catalog.entries) == 1
    assert catalog.problems and "junk_000001.mcap" in catalog.problems[0]
    assert not (root / CATALOG_NAME).exists()
