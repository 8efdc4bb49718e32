"""The records around an MCAP file's messages, parsed from its bytes: the header, the footer,
the summary section's groups and Statistics, and the Schema, Channel and Metadata records a
reader needs to name what it reads. Pure functions of the bytes; ``McapFile`` keeps what they
return. Every length is checked against the bytes it claims (``check_fits``).
"""

from __future__ import annotations

import struct

from trace_runtime.encoding.mcap_records import (
    FOOTER_SIZE,
    MAGIC,
    OP_FOOTER,
    OP_HEADER,
    OP_SUMMARY_OFFSET,
    RECORD_HEADER,
    check_fits,
    read_str,
)

__all__ = [
    "Statistics",
    "ends_in_footer",
    "parse_channel",
    "parse_header",
    "parse_metadata",
    "parse_schema",
    "parse_statistics",
    "summary_groups",
]

Statistics = tuple[int, int, int, dict[int, int]]
"""(message start ns, message end ns, chunk count, messages per channel id)."""


def parse_header(data: bytes, pos: int) -> tuple[str, int] | None:
    """The Header record at ``pos``: its profile and where it ends (None when cut short)."""
    if pos + 9 > len(data):
        return None
    opcode, length = RECORD_HEADER.unpack_from(data, pos)
    if opcode != OP_HEADER or pos + 9 + length > len(data):
        return None
    profile, _ = read_str(data, pos + 9)
    return profile, int(pos + 9 + length)


def ends_in_footer(data: bytes) -> bool:
    """Whether the file ends in a Footer record and the closing magic (its writer closed it)."""
    if len(data) < 8 + FOOTER_SIZE + 8 or data[-8:] != MAGIC:
        return False
    opcode, length = RECORD_HEADER.unpack_from(data, len(data) - 8 - FOOTER_SIZE)
    return bool(opcode == OP_FOOTER and length == 20)


def summary_groups(data: bytes, begin: int, end: int) -> dict[int, list[tuple[int, int]]]:
    """Summary Offset records: where each group of summary records lives."""
    groups: dict[int, list[tuple[int, int]]] = {}
    pos = begin
    while pos + 9 <= end:
        opcode, length = RECORD_HEADER.unpack_from(data, pos)
        check_fits(pos + 9, length, end)
        if opcode == OP_SUMMARY_OFFSET:
            group, start, size = struct.unpack_from("<BQQ", data, pos + 9)
            check_fits(start, size, len(data))
            groups.setdefault(group, []).append((start, start + size))
        pos += 9 + length
    return groups


def parse_statistics(data: bytes, body: int) -> Statistics:
    """A Statistics record's time range, chunk count and messages per channel."""
    (chunk_count,) = struct.unpack_from("<I", data, body + 8 + 2 + 4 + 4 + 4)
    start, end = struct.unpack_from("<QQ", data, body + 8 + 2 + 4 + 4 + 4 + 4)
    (map_len,) = struct.unpack_from("<I", data, body + 42)
    counts: dict[int, int] = {}
    pos = body + 46
    check_fits(pos, map_len, len(data))
    while pos < body + 46 + map_len:
        channel_id, n = struct.unpack_from("<HQ", data, pos)
        counts[channel_id] = n
        pos += 10
    return start, end, chunk_count, counts


def parse_schema(data: bytes, body: int) -> tuple[int, str]:
    """A Schema record's id and name."""
    (schema_id,) = struct.unpack_from("<H", data, body)
    name, _ = read_str(data, body + 2)
    return schema_id, name


def parse_channel(data: bytes, body: int) -> tuple[int, str]:
    """A Channel record's id and topic."""
    channel_id, _schema_id = struct.unpack_from("<HH", data, body)
    topic, _ = read_str(data, body + 4)
    return channel_id, topic


def parse_metadata(data: bytes, body: int) -> tuple[str, dict[str, str]]:
    """A Metadata record's name and key-value map."""
    name, pos = read_str(data, body)
    (map_len,) = struct.unpack_from("<I", data, pos)
    pos += 4
    stop = pos + map_len
    check_fits(pos, map_len, len(data))
    values: dict[str, str] = {}
    while pos < stop:
        key, pos = read_str(data, pos)
        value, pos = read_str(data, pos)
        values[key] = value
    return name, values
