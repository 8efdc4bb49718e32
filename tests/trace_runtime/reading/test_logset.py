"""The one owner of a multi-file log: which files, which copy of a segment, what failed."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.errors import LogReadError
from trace_runtime.reading.copies import copy_rank
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tiers import compact


def _root(tmp_path: Path, log_writer: Callable[..., AuditLogger], cycles: int = 30) -> Path:
    root = tmp_path / "root"
    log_writer(root, cycles, config=LoggerConfig(threaded=False, max_segment_s=1.0))
    return root


def test_an_empty_segment_after_a_power_cut_is_a_problem_not_a_failure(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = _root(tmp_path, log_writer)
    cycles = [c.cycle for c in open_log(root).iter_cycles()]
    (root / "hot" / "amr-1_000099.mcap").write_bytes(b"")
    (root / "hot" / "notes.mcap").write_bytes(b"not mcap at all")
    log = open_log(root)
    assert [c.cycle for c in log.iter_cycles()] == cycles
    assert {(p.path.name, p.reason) for p in log.problems} == {
        ("amr-1_000099.mcap", "empty file"),
        ("notes.mcap", "not an MCAP file (bad magic)"),
    }


def test_a_single_unreadable_file_is_still_an_error(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(b"")
    with pytest.raises(LogReadError, match="empty file"):
        open_log(path)
    with pytest.raises(LogReadError, match="empty file"):
        open_log(tmp_path)  # a directory whose only file cannot be read says why


def test_a_lossless_cold_copy_is_read_before_a_lossy_warm_one(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    """Of a warm copy (summaries) and a cold one (lossless) of the same segments, every
    reader reads the cold one, so no two commands read two different copies."""
    root = _root(tmp_path, log_writer)
    full = [(c.cycle, c.payloads) for c in open_log(root).iter_cycles()]
    warm_root = tmp_path / "warm_root"
    shutil.copytree(root, warm_root)
    compact(root, "cold", older_than_ns=0, retention_ns=None)
    compact(warm_root, "warm", older_than_ns=0, retention_ns=None)
    shutil.copytree(warm_root / "warm", root / "warm", dirs_exist_ok=True)
    assert list((root / "warm").glob("*.mcap")) and list((root / "cold").glob("*.mcap"))
    log = open_log(root)
    assert {s.session.tier for s in log.segments} == {"cold"}
    assert {s.session.tier for s in log.shadowed} == {"warm"}
    assert [(c.cycle, c.payloads) for c in log.iter_cycles()] == full
    assert copy_rank(log.segments[0]) < copy_rank(log.shadowed[0])


def test_the_chain_is_checked_across_segments(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = _root(tmp_path, log_writer)
    log = open_log(root)
    assert len(log.segments) > 1
    links = list(log.iter_chain("amr-1"))
    assert len(links) == 30
    assert all(status.ok and status.link == "ok" for _, status in links)
    assert [c.payloads[TOPIC_SEAL] for c, _ in links] == [
        c.payloads[TOPIC_SEAL] for c in log.iter_cycles()
    ]


def test_a_byte_identical_copy_in_another_directory_is_read_once(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = _root(tmp_path, log_writer)
    cycles = [c.cycle for c in open_log(root).iter_cycles()]
    (root / "cold").mkdir()
    first = sorted((root / "hot").glob("*.mcap"))[0]
    shutil.copy2(first, root / "cold" / first.name)
    log = open_log(root)
    assert [c.cycle for c in log.iter_cycles()] == cycles
    assert [s.path.name for s in log.shadowed] == [first.name]


def test_a_finished_copy_ranks_before_a_recovered_copy_of_the_same_tier(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    """``copy_rank`` alone puts the intact file first: every reader that sorts copies by it
    (the log, verify, the fleet index) prefers the same one."""
    root = _root(tmp_path, log_writer)
    original = sorted((root / "hot").glob("*.mcap"))[0]
    (root / "hot" / "copy").mkdir()
    half = root / "hot" / "copy" / original.name
    half.write_bytes(original.read_bytes()[: original.stat().st_size // 2])
    log = open_log(root)
    (cut,) = [s for s in log.shadowed if s.path == half]
    (kept,) = [s for s in log.segments if s.path == original]
    assert copy_rank(kept) < copy_rank(cut)
    assert sorted([cut, kept], key=copy_rank) == [kept, cut]
