"""A log root read across tiers: one copy per segment, whichever tier it sits in."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tiers import compact


def test_a_segment_left_in_two_tiers_is_read_once(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = tmp_path / "root"
    log_writer(root, 30, config=LoggerConfig(threaded=False, max_segment_s=1.0))
    hot_files = sorted((root / "hot").glob("*.mcap"))
    kept_aside = tmp_path / "aside"
    kept_aside.mkdir()
    for path in hot_files:
        shutil.copy2(path, kept_aside / path.name)
    seals_before = [c.payloads[TOPIC_SEAL] for c in open_log(root).iter_cycles()]
    compact(root, "cold", older_than_ns=0, retention_ns=None)
    assert not list((root / "hot").glob("*.mcap"))
    # As if a compaction was interrupted after writing cold but before removing hot:
    shutil.copy2(kept_aside / hot_files[1].name, root / "hot" / hot_files[1].name)
    log = open_log(root)
    assert [s.path.parent.name for s in log.shadowed] == ["cold"]
    assert [c.payloads[TOPIC_SEAL] for c in log.iter_cycles()] == seals_before
    assert log.cycle_at(log.start_ns + 1_500_000_000).cycle == 15
