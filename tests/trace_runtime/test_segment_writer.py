"""``SegmentWriter``: one MCAP segment written a batch of whole cycles per chunk."""

from __future__ import annotations

import io

from trace_runtime.segment_writer import OutMessage, SegmentWriter
from trace_runtime.session import SessionInfo


def _segment_bytes(messages: list[OutMessage] | list[tuple[int, int, int, bytes]]) -> bytes:
    stream = io.BytesIO()
    session = SessionInfo(robot_id="r", period_ns=100_000_000)
    writer = SegmentWriter(stream, session)
    writer.write_batch(messages)
    writer.finish()
    return stream.getvalue()


def test_write_batch_takes_plain_tuples_and_out_messages_alike() -> None:
    rows = [(1, 0, 10, b'{"a":1}'), (2, 0, 10, b'{"b":2}'), (1, 1, 20, b'{"a":3}')]
    assert _segment_bytes([OutMessage(*row) for row in rows]) == _segment_bytes(rows)
