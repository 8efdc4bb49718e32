"""Reader edge cases: time lookups at chunk boundaries, empty and foreign segments."""

from __future__ import annotations

import struct
from pathlib import Path

import orjson
import pytest
from mcap.writer import Writer

from trace_runtime import AuditLogger, LoggerConfig, LogReadError, TimeOutOfRangeError, open_log
from trace_runtime.chain import digest
from trace_runtime.logger.segment_writer import CHUNK_TABLE_ATTACHMENT
from trace_runtime.reading.reader import open_segment
from trace_runtime.records import GENESIS
from trace_runtime.session import SessionInfo
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000


def _write_with_sensor_lead(path: Path, cycles: int, lead_ns: int) -> None:
    """One chunk per cycle; each cycle cites a camera frame taken ``lead_ns`` before it."""
    logger = AuditLogger(path, robot_id="amr-1", config=LoggerConfig(threaded=False))
    for i in range(cycles):
        t_ns = 10 * PERIOD_NS + i * PERIOD_NS
        with logger.cycle(t_ns) as c:
            c.sensor("/sensors/camera", {"frame": i}, t_ns=t_ns - lead_ns)
            c.action(synthetic_cycle(i)[2])
    logger.close()


def test_cycle_at_finds_the_cycle_when_sensor_readings_precede_it_by_several_chunks(
    tmp_path: Path,
) -> None:
    # A camera 250 ms behind a 10 Hz loop: every chunk starts 2.5 periods before its cycle,
    # so the chunks that start at or before t hold only cycles after t for three chunks.
    path = tmp_path / "lead.mcap"
    _write_with_sensor_lead(path, 20, lead_ns=250_000_000)
    segment = open_segment(path)
    for i in range(20):
        t_ns = 10 * PERIOD_NS + i * PERIOD_NS
        for probe in (t_ns, t_ns + PERIOD_NS // 2):
            found = segment.cycle_at(probe)
            assert found is not None and found.cycle == i, (i, probe)
    assert segment.cycle_at(10 * PERIOD_NS - 1) is None
    assert open_log(path).cycle_at(15 * PERIOD_NS + 10).cycle == 5


def _clean_log(tmp_path: Path) -> bytes:
    from tests.trace_runtime.conftest import write_log

    path = tmp_path / "clean.mcap"
    write_log(path, 6)
    return path.read_bytes()


def _read_everything(path: Path) -> None:
    segment = open_segment(path)
    assert segment.info.session.robot_id
    list(segment.iter_cycles())
    segment.chunks()
    segment.cycle_at(segment.start_ns)


def test_a_session_record_with_a_non_numeric_field_is_a_read_error(tmp_path: Path) -> None:
    data = bytearray(_clean_log(tmp_path))
    at = data.find(b"period_ns") + len(b"period_ns") + 4  # the value's first character
    data[at] = ord("x")
    path = tmp_path / "session.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(LogReadError, match="session"):
        _read_everything(path)


def test_a_chunk_table_attachment_running_past_the_file_is_a_read_error(tmp_path: Path) -> None:
    data = bytearray(_clean_log(tmp_path))
    media = b"application/x-trace-chunk-columns"
    at = data.find(media, data.find(CHUNK_TABLE_ATTACHMENT.encode())) + len(media)
    struct.pack_into("<Q", data, at, 10**6 + 4)  # the attachment's data length
    path = tmp_path / "table.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(LogReadError, match="damaged"):
        _read_everything(path)


def test_a_finished_foreign_segment_without_chunks_is_read_from_its_loose_messages(
    tmp_path: Path,
) -> None:
    # The mcap library, with chunking off, writes a summary whose Chunk Index group is empty.
    path = tmp_path / "unchunked.mcap"
    with path.open("wb") as f:
        writer = Writer(f, use_chunking=False)
        writer.start(profile="trace", library="other-robot")
        writer.add_metadata(
            "trace.session", SessionInfo(robot_id="c", period_ns=PERIOD_NS).to_metadata()
        )
        schema = writer.register_schema("trace.Seal", "jsonschema", b"{}")
        seal_channel = writer.register_channel("/trace/seal", "json", schema)
        prev = GENESIS
        for cycle in range(3):
            t_ns = cycle * PERIOD_NS
            seal = orjson.dumps(
                {"cycle": cycle, "t_ns": t_ns, "digests": {}, "prev": prev, "dropped": 0}
            )
            writer.add_message(seal_channel, t_ns, seal, t_ns, sequence=cycle)
            prev = digest(seal)
        writer.finish()
    segment = open_segment(path)
    assert segment.finished
    assert [c.cycle for c in segment.iter_cycles()] == [0, 1, 2]
    assert [c.cycle for c in segment.iter_cycles(reverse=True)] == [2, 1, 0]
    found = segment.cycle_at(PERIOD_NS + 1)
    assert found is not None and found.cycle == 1


@pytest.mark.parametrize("payload", [b"[1,2]", b"not json", b'{"cycle":"x"}', b'{"cycle":{}}'])
def test_an_unsealed_tail_whose_payload_is_not_a_layer_object_is_still_read(
    tmp_path: Path, payload: bytes
) -> None:
    path = tmp_path / "tail.mcap"
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="trace", library="other-robot")
        writer.add_metadata(
            "trace.session", SessionInfo(robot_id="c", period_ns=PERIOD_NS).to_metadata()
        )
        schema = writer.register_schema("trace.Action", "jsonschema", b"{}")
        channel = writer.register_channel("/trace/action", "json", schema)
        writer.add_message(channel, PERIOD_NS, payload, PERIOD_NS, sequence=1)
        writer.finish()
    (cycle,) = open_segment(path).iter_cycles()
    assert not cycle.sealed and cycle.t_ns == PERIOD_NS
    assert cycle.payloads == {"/trace/action": payload}


def test_an_empty_segment_does_not_stretch_the_log_back_to_time_zero(tmp_path: Path) -> None:
    root = tmp_path / "root"
    t0 = 1_700_000_000_000_000_000
    config = LoggerConfig(threaded=False)
    logger = AuditLogger(root, robot_id="r", config=config)
    for i in range(3):
        logger.log_cycle(t0 + i * PERIOD_NS, action=synthetic_cycle(i)[2])
    logger.close()
    AuditLogger(root, robot_id="r", config=config).close()  # a restart that logged nothing
    log = open_log(root)
    assert len(log.segments) == 2
    assert (log.start_ns, log.end_ns) == (t0, t0 + 2 * PERIOD_NS)
    assert [c.cycle for c in log.iter_cycles()] == [0, 1, 2]
    assert log.cycle_at(t0 + PERIOD_NS).cycle == 1
    with pytest.raises(TimeOutOfRangeError):
        log.cycle_at(t0 - 1)
