"""Retention deletes only old cold segments that verify, records each deletion first, and
never touches the hot or warm tier."""

from __future__ import annotations

from pathlib import Path

import orjson

from tests.trace_runtime.tier_logs import T0_NS, make_root
from trace_runtime.tiers import ColdOptions, compact, parse_duration
from trace_runtime.tiers.durations import DAY_NS
from trace_runtime.tiers.retention import RETENTION_LOG

SMALL_BLOCKS = ColdOptions(block_cycles=16)


def _segment_names(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.glob("*/*.mcap"))


def test_retention_deletes_only_old_cold_segments_that_verify(tmp_path: Path) -> None:
    root = tmp_path / "log"
    for days in (0, 10, 300, 400):
        make_root(root, cycles=20, t0_ns=T0_NS + days * DAY_NS, drop_at=None)
    # the newest is day 400: days 0 and 10 are past 183 days, 300 is not
    compact(root, "cold", older_than_ns=0, sources=["hot"], retention_ns=None, cold=SMALL_BLOCKS)
    segments = sorted((root / "cold").glob("*.mcap"))
    tampered = segments[1]
    data = bytearray(tampered.read_bytes())
    mark = data.find(b"/trace/cold/index")
    data[data.find(b"TCB\x01") + 100] ^= 0x01  # damage a block
    assert mark > 0
    tampered.write_bytes(bytes(data))
    report = compact(root, "cold", older_than_ns=parse_duration("1000d"))
    by_path = {r.path: r for r in report.retention}
    assert by_path[f"cold/{segments[0].name}"].status == "deleted"
    assert by_path[f"cold/{segments[1].name}"].status == "kept"
    assert "held: findings (damaged" in by_path[f"cold/{segments[1].name}"].detail
    assert len(by_path) == 2
    assert sorted(p.name for p in (root / "cold").glob("*.mcap")) == [s.name for s in segments[1:]]
    tombstones = [orjson.loads(line) for line in (root / RETENTION_LOG).read_bytes().splitlines()]
    assert [t["path"] for t in tombstones] == [f"cold/{segments[0].name}"]
    assert tombstones[0]["last_seal"] and tombstones[0]["sha256"]


def test_retention_never_deletes_hot_or_warm(tmp_path: Path) -> None:
    root = tmp_path / "log"
    for days in (0, 400):
        make_root(root, cycles=20, t0_ns=T0_NS + days * DAY_NS, drop_at=None)
    compact(root, "warm", older_than_ns=parse_duration("300d"))  # day 0 -> warm
    before = _segment_names(root)
    report = compact(root, "cold", older_than_ns=parse_duration("1000d"), retention_ns=DAY_NS)
    assert report.retention == []
    assert _segment_names(root) == before == ["hot/amr-1_000001.mcap", "warm/amr-1_000000.mcap"]
