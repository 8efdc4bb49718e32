"""The MCAP records the segment writer builds by hand: the fixed headers and opcodes of
messages, chunks and message indexes, one message batch laid out as a chunk holds it, and a
record of the `mcap` library's own serialised to bytes. ``OutMessage`` is what the logger's
writer hands the segment writer.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

from mcap.data_stream import RecordBuilder

__all__ = [
    "CHUNK_HEADER",
    "INDEX_ENTRY",
    "INDEX_HEADER",
    "MESSAGE_HEADER",
    "OPCODE_CHANNEL",
    "OPCODE_CHUNK",
    "OPCODE_MESSAGE",
    "OPCODE_MESSAGE_INDEX",
    "OPCODE_METADATA",
    "OPCODE_SCHEMA",
    "U64",
    "MessageFields",
    "OutMessage",
    "builder_bytes",
    "encode_record",
    "message_records",
]

MESSAGE_HEADER = struct.Struct("<BQHIQQ")
CHUNK_HEADER = struct.Struct("<BQQQQII")  # opcode, length, start, end, size, crc, compression len
INDEX_HEADER = struct.Struct("<BQHI")  # opcode, length, channel id, entries byte length
INDEX_ENTRY = struct.Struct("<QQ")
U64 = struct.Struct("<Q")
OPCODE_CHUNK = 0x06
OPCODE_MESSAGE_INDEX = 0x07
OPCODE_MESSAGE = 0x05
OPCODE_SCHEMA = 0x03
OPCODE_CHANNEL = 0x04
OPCODE_METADATA = 0x0C


def encode_record(record: object) -> bytes:
    builder = RecordBuilder()
    record.write(builder)  # type: ignore[attr-defined]
    return builder_bytes(builder)


def builder_bytes(builder: RecordBuilder) -> bytes:
    """The builder's bytes (the mcap library leaves ``end`` unannotated)."""
    return bytes(builder.end())  # type: ignore[no-untyped-call]


def message_records(
    messages: Sequence[MessageFields],
) -> tuple[bytearray, dict[int, bytearray], int, int]:
    """A batch's message records as one chunk holds them, each channel's message-index
    entries (packed as they are made), and the batch's first and last log time."""
    records = bytearray()
    indexes: dict[int, bytearray] = {}
    start = end = messages[0][2]
    pack, pack_entry = MESSAGE_HEADER.pack, INDEX_ENTRY.pack
    for channel_id, sequence, log_time, data in messages:
        index = indexes.get(channel_id)
        if index is None:
            index = indexes[channel_id] = bytearray()
        index += pack_entry(log_time, len(records))
        records += pack(OPCODE_MESSAGE, 22 + len(data), channel_id, sequence, log_time, log_time)
        records += data
        if log_time < start:
            start = log_time
        elif log_time > end:
            end = log_time
    return records, indexes, start, end


class OutMessage(NamedTuple):
    """One message to write: channel id, per-channel sequence, log time and data.

    A tuple, so the logger's writer may hand ``write_batch`` plain 4-tuples in this order: it
    makes several per cycle, and a tuple costs a fraction of a class instance to build."""

    channel_id: int
    sequence: int
    log_time_ns: int
    data: bytes


MessageFields = tuple[int, int, int, bytes]
"""What ``write_batch`` reads from each message: ``OutMessage`` or a plain tuple like it."""
