"""doctor on a profile 1.4 log: declared recordings and their sealed windows conform; a
``recordings`` key readers would drop is named."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from tests.outside import cli
from tests.trace_runtime.logger.test_recording_seals import RECORDER, run_robot


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run = tmp_path_factory.mktemp("run")
    bag = run / "ward_bag"
    subprocess.run([sys.executable, str(RECORDER), str(bag)], check=True, capture_output=True)
    run_robot(run / "log", bag, 50)
    return run / "log"


def test_a_log_that_seals_its_recording_conforms(root: Path) -> None:
    done = cli("doctor", root)
    assert done.returncode == 0, done.stdout + done.stderr


def test_a_recordings_key_readers_would_drop_is_named(root: Path, tmp_path: Path) -> None:
    [segment] = (root / "hot").glob("*.mcap")
    forged = tmp_path / segment.name
    with segment.open("rb") as stream:
        reader = make_reader(stream)
        metadata = list(reader.iter_metadata())
        rows = list(reader.iter_messages())
    with forged.open("wb") as stream:
        writer = Writer(stream)
        writer.start(profile="trace", library="forger")
        for record in metadata:
            values = dict(record.metadata)
            if record.name == "trace.session":
                values["recordings"] = json.dumps({"ward_bag": 5, "..": "x"})
            writer.add_metadata(record.name, values)
        ids: dict[int, int] = {}
        for schema, channel, message in rows:
            if channel.id not in ids:
                assert schema is not None
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_id
                )
            writer.add_message(
                ids[channel.id],
                message.log_time,
                message.data,
                message.publish_time,
                sequence=message.sequence,
            )
        writer.finish()
    done = cli("doctor", forged)
    assert done.returncode == 1
    assert "recordings is not a JSON object" in done.stdout
