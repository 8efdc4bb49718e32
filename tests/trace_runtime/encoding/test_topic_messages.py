"""``McapFile.topic_messages``: one topic's messages without building the others, exactly
what filtering ``iter_messages`` gives, damaged chunks skipped and recorded alike."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.trace_runtime.tlog.test_checkpoints import _sync, _write
from trace_runtime import open_segment
from trace_runtime.errors import LogReadError
from trace_runtime.records import TOPIC_ACTION, TOPIC_CHECKPOINT, TOPIC_SEAL

TOPICS = (TOPIC_CHECKPOINT, TOPIC_SEAL, TOPIC_ACTION, "/sensors/lidar", "/nowhere")


@pytest.fixture(scope="module")
def log_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("topic") / "run.mcap"
    _write(path, 240, _sync(batch_cycles=10, checkpoint_interval_s=1.0)).close()
    return path.read_bytes()


def _both(path: Path, topic: str) -> tuple[object, object]:
    def read(filtered: bool) -> object:
        try:
            segment = open_segment(path)
        except LogReadError as err:
            return ("refused", str(err))
        if filtered:
            got = list(segment.topic_messages(topic))
        else:
            got = [m for m in segment.iter_messages() if m.topic == topic]
        return got, segment.skipped_chunks

    return read(False), read(True)


@pytest.mark.parametrize("topic", TOPICS)
def test_one_topic_is_the_filtered_read(tmp_path: Path, log_bytes: bytes, topic: str) -> None:
    path = tmp_path / "run.mcap"
    path.write_bytes(log_bytes)
    whole, filtered = _both(path, topic)
    assert whole == filtered
    if topic == TOPIC_CHECKPOINT:
        assert len(whole[0]) >= 20  # type: ignore[index]


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    edits=st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), min_size=1, max_size=3),
    cut=st.one_of(st.none(), st.floats(0.3, 1)),
    topic=st.sampled_from(TOPICS),
)
def test_damaged_files_give_the_same_messages_and_skipped_chunks(
    tmp_path: Path, log_bytes: bytes, edits: list[tuple[float, int]], cut: float | None, topic: str
) -> None:
    data = bytearray(log_bytes)
    for at, byte in edits:
        data[min(len(data) - 1, 8 + int(at * (len(data) - 8)))] = byte
    if cut is not None:
        data = data[: int(len(data) * cut)]
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(data))
    logging.disable(logging.WARNING)
    try:
        whole, filtered = _both(path, topic)
    finally:
        logging.disable(logging.NOTSET)
    assert whole == filtered
