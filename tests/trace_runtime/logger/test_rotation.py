"""Segments rotate by duration and size, and the hash chain links across them and restarts."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from mcap.reader import make_reader

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.records import GENESIS, TOPIC_SEAL
from trace_runtime.testing import synthetic_cycle


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
    _, _, action, _ = synthetic_cycle(0)
    second.log_cycle(5_000_000_000, action=action)
    second.close()
    assert _chain_ok(root) == list(range(11))


def test_threaded_synchronous_and_batched_writers_seal_identically(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    configs = {
        "threaded": LoggerConfig(threaded=True),
        "sync": LoggerConfig(threaded=False),
        "sync-batched": LoggerConfig(threaded=False, batch_cycles=10),
    }
    seals = {}
    for name, config in configs.items():
        log_writer(tmp_path / f"{name}.mcap", 25, config=config)
        log = open_log(tmp_path / f"{name}.mcap")
        seals[name] = [c.payloads[TOPIC_SEAL] for c in log.iter_cycles()]
        if name == "sync-batched":
            assert log.segments[0].info.chunk_count <= 4  # 10 + 10 + 5 cycles (+ checkpoint)
    assert len(seals["sync"]) == 25
    assert seals["threaded"] == seals["sync"] == seals["sync-batched"]


def test_a_damaged_newest_segment_does_not_stop_the_robot_from_logging(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    root = tmp_path / "root"
    log_writer(root, 25, config=LoggerConfig(threaded=False, max_segment_s=1.0))
    newest = sorted((root / "hot").glob("*.mcap"))[-1]
    # The file still opens (its summary is intact) but its last chunks fail their CRC.
    data = bytearray(newest.read_bytes())
    for chunk in open_log(newest).segments[0].chunks()[-2:]:
        data[chunk.offset + 80 : chunk.offset + 96] = b"\x00" * 16
    newest.write_bytes(bytes(data))
    readable = [c for c in open_log(newest).iter_cycles() if c.sealed]
    logger = AuditLogger(root, robot_id="amr-1", config=LoggerConfig(threaded=False))
    logger.log_cycle(9_000_000_000, action=synthetic_cycle(0)[2])
    logger.close()
    # The damaged chunks are stepped over: the chain continues from the newest seal that
    # can still be read.
    assert readable[-1].cycle < 24
    resumed = open_log(logger.stats.segments[-1]).get_cycle(readable[-1].cycle + 1)
    assert logger.stats.written == 1
    assert resumed is not None and resumed.seal is not None
    assert resumed.seal.prev == digest(readable[-1].payloads[TOPIC_SEAL])
