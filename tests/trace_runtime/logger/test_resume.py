"""Where a robot's chain goes on in a log root (``trace_runtime.logger.resume``): after the newest
segment, from the copy every reader reads, from names alone when there is nothing to resume."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.logger.resume import FRESH, ResumePoint, resume_point
from trace_runtime.records import GENESIS, TOPIC_SEAL
from trace_runtime.tiers import compact


def _root(tmp_path: Path, log_writer: Callable[..., AuditLogger], cycles: int = 25) -> Path:
    root = tmp_path / "root"
    log_writer(root, cycles, config=LoggerConfig(threaded=False, max_segment_s=1.0))
    return root


def _after_last_cycle(root: Path, robot: str = "amr-1") -> ResumePoint:
    log = open_log(root)
    last = list(log.iter_cycles())[-1]
    numbers = [s.session.segment for s in log.segments if s.session.robot_id == robot]
    return ResumePoint(last.cycle + 1, digest(last.payloads[TOPIC_SEAL]), max(numbers) + 1)


def test_a_root_without_the_robot_starts_a_fresh_chain(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = _root(tmp_path, log_writer)
    assert resume_point(root, "another") == FRESH == ResumePoint(0, GENESIS, 0)
    assert resume_point(tmp_path / "empty", "amr-1") == FRESH


def test_the_chain_goes_on_after_the_newest_segment(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = _root(tmp_path, log_writer)
    assert len(list((root / "hot").glob("*.mcap"))) > 1
    assert resume_point(root, "amr-1") == _after_last_cycle(root)


def test_the_intact_copy_wins_over_a_truncated_copy_of_the_newest_segment(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    """A half copy beside the newest segment (in the log, so ``copy_rank`` decides): the
    chain goes on from the intact file's last seal, not from the middle of the segment."""
    root = _root(tmp_path, log_writer)
    want = _after_last_cycle(root)
    newest = sorted((root / "hot").glob("*.mcap"))[-1]
    (root / "hot" / "a-copy").mkdir()
    half = root / "hot" / "a-copy" / newest.name
    half.write_bytes(newest.read_bytes()[: newest.stat().st_size // 2])
    assert resume_point(root, "amr-1") == want


def test_a_newest_segment_without_a_seal_is_passed_over(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    """Killed before its first write: the segment number goes on, the chain from the seal
    before it."""
    root = _root(tmp_path, log_writer)
    want = _after_last_cycle(root)
    empty = root / "hot" / f"amr-1_{want.next_segment:06d}.mcap"
    empty.write_bytes(b"")
    assert resume_point(root, "amr-1") == want._replace(next_segment=want.next_segment + 1)


def test_a_cut_hot_copy_beside_the_intact_cold_segment_gives_way_to_it(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    """The newest segment compacted to cold, a half copy of its hot file left in hot/: the
    lower tier does not win over the intact copy (``copy_rank``: finished first)."""
    root = _root(tmp_path, log_writer)
    want = _after_last_cycle(root)
    newest = sorted((root / "hot").glob("*.mcap"))[-1]
    original = newest.read_bytes()
    compact(root, "cold", older_than_ns=0, retention_ns=None)
    assert (root / "cold" / newest.name).is_file() and not newest.exists()
    newest.write_bytes(original[: len(original) // 2])
    assert resume_point(root, "amr-1") == want
