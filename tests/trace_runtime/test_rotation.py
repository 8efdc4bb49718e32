"""Segments rotate by duration and size, and the hash chain links across them and restarts."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mcap.reader import make_reader

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.records import GENESIS, TOPIC_SEAL


def _chain_ok(root: Path) -> list[int]:
    log = open_log(root)
    prev = GENESIS
    numbers = []
    for segment in log.segments:
        assert segment.session.prev_seal == prev  # each segment names the seal before it
        for cycle in segment.iter_cycles():
            assert cycle.seal is not None and cycle.seal.prev == prev
            assert cycle.seal.digests == cycle.digests()
            prev = digest(cycle.payloads[TOPIC_SEAL])
            numbers.append(cycle.cycle)
    return numbers


def test_rotation_by_duration_gives_contiguous_linked_segments(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = tmp_path / "root"
    logger = log_writer(root, 45, config=LoggerConfig(threaded=False, max_segment_s=1.0))
    assert len(logger.stats.segments) == 5  # 4.5 s of cycles in 1 s segments
    assert _chain_ok(root) == list(range(45))
    firsts = [s.session.first_cycle for s in open_log(root).segments]
    assert firsts == [0, 10, 20, 30, 40]


def test_rotation_by_size(tmp_path: Path, log_writer: Callable[..., AuditLogger]) -> None:
    root = tmp_path / "root"
    limit = 45_000
    logger = log_writer(root, 30, config=LoggerConfig(threaded=False, max_segment_bytes=limit))
    assert len(logger.stats.segments) > 2
    for path in logger.stats.segments:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None
        seal = next(i for i, c in summary.channels.items() if c.topic == "/trace/seal")
        starts = [
            c.chunk_start_offset for c in summary.chunk_indexes if seal in c.message_index_offsets
        ]
        # Rotation is checked before each batch: no cycle starts past the limit.
        assert starts and max(starts) < limit
    assert _chain_ok(root) == list(range(30))


def test_a_restarted_robot_continues_its_chain_and_cycle_numbers(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = tmp_path / "root"
    log_writer(root, 10)
    second = AuditLogger(root, robot_id="amr-1", config=LoggerConfig(threaded=False))
    from trace_runtime.testing import synthetic_cycle

    _, _, action, _ = synthetic_cycle(0)
    second.log_cycle(5_000_000_000, action=action)
    second.close()
    assert _chain_ok(root) == list(range(11))


def test_threaded_and_synchronous_writers_seal_identically(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    a = tmp_path / "a.mcap"
    b = tmp_path / "b.mcap"
    log_writer(a, 25, config=LoggerConfig(threaded=True))
    log_writer(b, 25, config=LoggerConfig(threaded=False))
    seals_a = [c.payloads[TOPIC_SEAL] for c in open_log(a).iter_cycles()]
    seals_b = [c.payloads[TOPIC_SEAL] for c in open_log(b).iter_cycles()]
    assert seals_a == seals_b and len(seals_a) == 25
