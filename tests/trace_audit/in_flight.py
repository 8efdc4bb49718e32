"""A crashed segment cut while a cycle was being written: its layer messages, no seal."""

from __future__ import annotations

from pathlib import Path

from mcap.writer import Writer

from trace_runtime import open_segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.session import SESSION_METADATA


def cut_in_flight(
    src: Path, dst: Path, *, unsealed: int | None = None, finished: bool = False
) -> Path:
    """Copy segment ``src`` to ``dst`` as a robot killed mid-write leaves it: no summary, no
    footer, and cycle ``unsealed`` (default: the last one) without its seal.

    Small chunks are flushed as a logger flushes its batches, so what precedes the cut reads
    back whole. Leaving out a seal other than the last one makes an unsealed cycle in the
    middle of a crashed segment: that one is a finding, not the cycle in flight.
    ``finished=True`` closes the file instead: a closed segment whose last cycle has no seal
    was not cut by a crash, so that unsealed cycle is a finding too."""
    segment = open_segment(src)
    messages = list(segment.iter_messages())
    seals = [m.sequence for m in messages if m.topic == TOPIC_SEAL]
    drop = seals[-1] if unsealed is None else unsealed
    with open(dst, "wb") as f:
        writer = Writer(f, chunk_size=2048)
        writer.start(profile="trace", library="tests")
        writer.add_metadata(SESSION_METADATA, segment.metadata[SESSION_METADATA])
        channels: dict[str, int] = {}
        for msg in messages:
            if msg.topic == TOPIC_SEAL and msg.sequence == drop:
                continue
            if msg.topic not in channels:
                schema = writer.register_schema(name=msg.topic, encoding="jsonschema", data=b"{}")
                channels[msg.topic] = writer.register_channel(
                    topic=msg.topic, message_encoding="json", schema_id=schema
                )
            writer.add_message(
                channels[msg.topic],
                msg.log_time_ns,
                msg.data,
                msg.log_time_ns,
                sequence=msg.sequence,
            )
        if finished:
            writer.finish()  # type: ignore[no-untyped-call]
        else:
            writer.flush()  # the last batch reached the disk; the summary never did
    return dst
