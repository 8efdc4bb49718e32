"""Our segments are standard MCAP: the `mcap` library reads, indexes and seeks them, every
message is valid against its published schema, and our reader reads the library's files."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import jsonschema
import orjson
from mcap.reader import make_reader
from mcap.writer import Writer

from trace_runtime import AuditLogger, open_log
from trace_runtime.chain import digest
from trace_runtime.records import GENESIS
from trace_runtime.schemas import schema_name
from trace_runtime.session import SessionInfo

SCHEMAS = Path(__file__).resolve().parents[3] / "schemas"


def test_mcap_library_reads_summary_chunk_indexes_and_metadata(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    path = tmp_path / "log.mcap"
    log_writer(path, 30)
    with path.open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "trace"
        summary = reader.get_summary()
        assert summary is not None
        seals = [c for c in summary.channels.values() if c.topic == "/trace/seal"]
        assert summary.statistics.channel_message_counts[seals[0].id] == 30
        assert len(summary.chunk_indexes) >= 30  # a chunk per synchronous commit
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert metadata["trace.session"]["robot_id"] == "amr-1"
        assert {c.topic for c in summary.channels.values()} >= {
            "/trace/perception",
            "/trace/belief",
            "/trace/action",
            "/trace/execution",
            "/trace/seal",
            "/sensors/lidar",
        }


def test_time_indexed_seek_with_the_mcap_library(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    path = tmp_path / "log.mcap"
    log_writer(path, 30)
    with path.open("rb") as f:
        reader = make_reader(f)
        got = list(
            reader.iter_messages(
                topics=["/trace/seal"], starting_at=1_000_000_000, ending_before=1_500_000_000
            )
        )
    assert [m.sequence for _, _, m in got] == [10, 11, 12, 13, 14]


def test_every_message_validates_against_its_schema_file(
    tmp_path: Path, log_writer: Callable[..., AuditLogger]
) -> None:
    path = tmp_path / "log.mcap"
    log_writer(path, 5)
    validators = {}
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert schema is not None and schema.encoding == "jsonschema"
            if channel.topic not in validators:
                published = json.loads((SCHEMAS / f"{schema.name}.json").read_text())
                assert json.loads(schema.data) == published  # the log carries the same schema
                validators[channel.topic] = jsonschema.Draft202012Validator(published)
            validators[channel.topic].validate(orjson.loads(message.data))
    assert len(validators) >= 6  # four layers, seal, sensor (+ checkpoints)


def test_our_reader_reads_a_log_written_with_the_plain_mcap_writer(tmp_path: Path) -> None:
    """A robot in another language writing the profile with any MCAP library is readable."""
    path = tmp_path / "foreign.mcap"
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="trace", library="other-robot")
        session = SessionInfo(robot_id="cpp-bot", period_ns=100_000_000)
        writer.add_metadata("trace.session", session.to_metadata())
        ids = {}
        for topic in ("/trace/action", "/trace/seal"):
            name = schema_name(topic)
            sid = writer.register_schema(
                name, "jsonschema", (SCHEMAS / f"{name}.json").read_bytes()
            )
            ids[topic] = writer.register_channel(topic, "json", sid)
        prev = GENESIS
        for cycle in range(3):
            t = cycle * 100_000_000
            action = orjson.dumps(
                {"cycle": cycle, "t_ns": t, "command": "STOP", "rationale": {"text": "why"}}
            )
            seal = orjson.dumps(
                {
                    "cycle": cycle,
                    "t_ns": t,
                    "digests": {"/trace/action": digest(action)},
                    "prev": prev,
                    "dropped": 0,
                }
            )
            writer.add_message(ids["/trace/action"], t, action, t, sequence=cycle)
            writer.add_message(ids["/trace/seal"], t, seal, t, sequence=cycle)
            prev = digest(seal)
        writer.finish()
    log = open_log(path)
    cycles = list(log.iter_cycles())
    assert [c.cycle for c in cycles] == [0, 1, 2]
    assert all(c.action is not None and c.action.command == "STOP" for c in cycles)
    assert all(c.seal is not None and c.seal.digests == c.digests() for c in cycles)
    assert log.cycle_at(150_000_000).cycle == 1
