"""Decoding one MCAP chunk record into messages, within the reader's limits.

A chunk is decompressed (none, zstd or lz4: whatever MCAP allows), checked against its CRC and
its declared size, and split into messages. A chunk may never make the reader produce more
than it declares nor more than ``ReadLimits`` allow; what it would is a ``LogLimitError``,
what is damaged a ``LogReadError`` (or one of ``mcap_records.DAMAGE``), for the file to decide.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import fields
from pathlib import Path

import lz4.frame
import zstandard

from trace_runtime.encoding.cycles import RawMessage, raw_message
from trace_runtime.encoding.mcap_records import (
    CHUNK_FIXED,
    MESSAGE_FIXED,
    OP_CHANNEL,
    OP_CHUNK,
    OP_MESSAGE,
    RECORD_HEADER,
    check_fits,
    read_str,
)
from trace_runtime.errors import LogLimitError, LogReadError
from trace_runtime.read_limits import ReadLimits

__all__ = ["ChunkDecoder"]

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
"""A message record's header (opcode, length) and fixed fields (channel, sequence, log
time, publish time): 31 bytes, one unpack."""

_RAW_MESSAGE_SLOTS = (
    object.__new__,
    *(getattr(RawMessage, f.name).__set__ for f in fields(RawMessage)),
)


class ChunkDecoder:
    """Decodes the chunks of one file; owns the file's zstd context (a file is read by one
    thread at a time)."""

    def __init__(self, path: Path, limits: ReadLimits) -> None:
        self._name = str(path)
        self._limits = limits
        self._zstd_context: zstandard.ZstdDecompressor | None = None

    @property
    def _zstd(self) -> zstandard.ZstdDecompressor:
        # Made on first use (~25 us): a log of many segments is opened whole, and a seek
        # decodes chunks of one or two of them.
        if self._zstd_context is None:
            self._zstd_context = zstandard.ZstdDecompressor()
        return self._zstd_context

    def decode(
        self, data: bytes, offset: int, topics: dict[int, str], only: str | None = None
    ) -> list[RawMessage]:
        """The messages of the chunk record at ``offset`` of ``data``; a Channel record inside
        the chunk adds its topic to ``topics``. ``only``: just the messages on that topic
        (every record is still read and checked as for all of them: the same errors)."""
        opcode, length = RECORD_HEADER.unpack_from(data, offset)
        if opcode != OP_CHUNK:
            raise LogReadError(self._name, f"no chunk record at offset {offset}")
        check_fits(offset + 9, length, len(data))
        body = offset + 9
        _start, _end, size, crc = CHUNK_FIXED.unpack_from(data, body)
        compression, pos = read_str(data, body + 28)
        (records_len,) = struct.unpack_from("<Q", data, pos)
        pos += 8
        check_fits(pos, records_len, body + length)
        raw = self._decompress(compression, data[pos : pos + records_len], size, offset)
        if crc and zlib.crc32(raw) != crc:
            raise LogReadError(self._name, f"chunk at offset {offset} fails its CRC")
        return self._records(raw, offset, self._limits.chunk_records(records_len), topics, only)

    def _decompress(self, compression: str, compressed: bytes, size: int, offset: int) -> bytes:
        """A chunk's records, never more than its declared size nor the limits."""
        cap = self._limits.chunk_bytes(len(compressed))
        if size > cap:
            raise LogLimitError(
                self._name,
                f"chunk at offset {offset} declares {size} bytes decompressed from "
                f"{len(compressed)}, over the limit of {cap} bytes",
            )
        if compression == "":
            raw = bytes(compressed)
        elif compression == "zstd":
            raw = self._unzstd(compressed, size, offset)
        elif compression == "lz4":
            try:
                raw = lz4.frame.LZ4FrameDecompressor().decompress(compressed, max_length=size + 1)
            except RuntimeError as err:
                raise LogReadError(self._name, f"chunk at offset {offset}: {err}") from err
        else:
            raise LogReadError(
                self._name, f"chunk at offset {offset}: unknown compression {compression!r}"
            )
        if len(raw) > size:
            raise self._inflates_past(offset, size)
        if len(raw) != size:
            raise LogReadError(
                self._name,
                f"chunk at offset {offset} decompresses to {len(raw)} bytes, not the "
                f"{size} it declares",
            )
        return raw

    def _unzstd(self, compressed: bytes, size: int, offset: int) -> bytes:
        """Decompress a zstd chunk, producing at most one byte more than it declares."""
        content = zstandard.frame_content_size(compressed)
        if content > size:  # the frame's own claim; -1 when it makes none
            raise self._inflates_past(offset, size)
        if content == size:
            return self._zstd.decompress(compressed, max_output_size=size)
        # No size in the frame: stream, so that "more than declared" is told from damage.
        reader = self._zstd.stream_reader(compressed)
        parts, got = [], 0
        while got <= size:
            part = reader.read(size + 1 - got)
            if not part:
                break
            parts.append(part)
            got += len(part)
        return b"".join(parts)

    def _inflates_past(self, offset: int, size: int) -> LogLimitError:
        return LogLimitError(
            self._name, f"chunk at offset {offset} inflates past its declared {size} bytes"
        )

    def _records(
        self, raw: bytes, offset: int, most: int, topics: dict[int, str], only: str | None
    ) -> list[RawMessage]:
        # The innermost loop of every read (8-10 records a decision cycle): locals only,
        # the bounds checks written out. Wherever 31 bytes remain, the record is read as a
        # message in one unpack (``_MESSAGE_HEAD``: header and fixed fields), whatever its
        # opcode, since nearly every record is one; its ``RawMessage`` is filled slot by slot
        # here, without a call per message (``cycles.raw_message`` does the same). Anything
        # else, or a message that does not fit, takes the general path below.
        messages: list[RawMessage] = []
        append = messages.append
        header = RECORD_HEADER.unpack_from
        message_head = _MESSAGE_HEAD.unpack_from
        fixed = MESSAGE_FIXED.unpack_from
        topic_of = topics.get
        new, set_topic, set_sequence, set_log_time, set_data = _RAW_MESSAGE_SLOTS
        pos, end, count = 0, len(raw), 0
        while pos + 9 <= end:
            if pos + 31 <= end:
                opcode, length, channel_id, sequence, log_time, _publish = message_head(raw, pos)
                stop = pos + 9 + length
                if opcode == OP_MESSAGE and length >= 22 and stop <= end:
                    count += 1
                    if count > most:
                        raise self._flood(offset, most)
                    topic = topic_of(channel_id)
                    if topic is None:
                        raise self._unknown_channel(offset)
                    if only is not None and topic != only:
                        pos = stop
                        continue
                    message = new(RawMessage)
                    set_topic(message, topic)
                    set_sequence(message, sequence)
                    set_log_time(message, log_time)
                    set_data(message, raw[pos + 31 : stop])
                    append(message)
                    pos = stop
                    continue
            opcode, length = header(raw, pos)
            body = pos + 9
            pos = body + length
            if pos > end:
                check_fits(body, length, end)
            count += 1
            if count > most:
                raise self._flood(offset, most)
            if opcode == OP_MESSAGE:
                channel_id, sequence, log_time, _publish = fixed(raw, body)
                topic = topics.get(channel_id)
                if topic is None:
                    raise self._unknown_channel(offset)
                if only is None or topic == only:
                    append(raw_message(topic, sequence, log_time, raw[body + 22 : pos]))
            elif opcode == OP_CHANNEL:
                channel_id, _schema = struct.unpack_from("<HH", raw, body)
                topic_name, _ = read_str(raw, body + 4)
                topics[channel_id] = topic_name
        return messages

    def _unknown_channel(self, offset: int) -> LogReadError:
        return LogReadError(self._name, f"chunk at offset {offset}: message on unknown channel")

    def _flood(self, offset: int, most: int) -> LogLimitError:
        return LogLimitError(
            self._name,
            f"chunk at offset {offset} holds more than {most} records for its "
            "compressed size (a flood, not a log)",
        )
