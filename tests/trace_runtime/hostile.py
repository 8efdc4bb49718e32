"""Hostile TRACE segments built from the outside, with nothing but the plain ``mcap`` library.

An investigator opens files an attacker may have prepared. These builders write the files
such an attacker would: a valid MCAP header of profile ``trace`` and a ``trace.session``
metadata record (so the file reaches the deep code), then chunks that are bombs or floods.
The ``mcap`` Writer refuses to write a chunk whose declared size lies, so chunks are
written as records with ``mcap.records`` (the library's own record encoders).

Used by ``tests/trace_runtime/test_hostile.py``, ``tests/trace_audit/cli/test_hostile.py``
and ``bench/bench_hostile.py``.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import lz4.frame
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"
GIB = 1 << 30
TOPICS = (
    "/trace/perception",
    "/trace/belief",
    "/trace/action",
    "/trace/execution",
    "/trace/seal",
    "/sensors/lidar",
)
"""Channel ids 1.. in this order."""
SEAL_CHANNEL = 5


def session(**override: str) -> dict[str, str]:
    """A valid ``trace.session`` map (PROFILE section 2), with some keys replaced."""
    values = {
        "robot_id": "amr-7",
        "period_ns": "100000000",
        "software_version": "1",
        "policy_version": "1",
        "clock": "sim",
        "segment": "0",
        "prev_seal": "0" * 64,
        "first_cycle": "0",
        "tier": "hot",
        "profile_version": "1",
    }
    values.update(override)
    return values


@dataclass(frozen=True)
class RawChunk:
    """A chunk record as it will sit in the file; ``declared`` may lie."""

    compression: str
    data: bytes
    declared: int
    start_ns: int = 0
    end_ns: int = 0
    crc: int = 0


def message_records(messages: Iterable[tuple[int, int, int, bytes]]) -> bytes:
    """Message records (channel id, sequence, log time, data), as a chunk holds them."""
    out = RecordBuilder()
    for channel_id, sequence, t_ns, data in messages:
        Message(
            channel_id=channel_id, log_time=t_ns, data=data, publish_time=t_ns, sequence=sequence
        ).write(out)
    return bytes(out.end())


def zstd_chunk(raw: bytes, *, declared: int | None = None, start_ns: int = 0) -> RawChunk:
    return RawChunk(
        "zstd",
        zstandard.ZstdCompressor().compress(raw),
        len(raw) if declared is None else declared,
        start_ns,
        start_ns,
        zlib.crc32(raw),
    )


def _zero_stream(total: int, compress: Callable[[bytes], bytes], step: int = 1 << 24) -> bytes:
    parts = []
    zeros = bytes(step)
    left = total
    while left > 0:
        parts.append(compress(zeros[: min(step, left)]))
        left -= step
    return b"".join(parts)


def zstd_zeros(total: int, *, content_size: bool = True) -> bytes:
    """A zstd frame of ``total`` zero bytes, compressed without ever holding them."""
    compressor = zstandard.ZstdCompressor(level=1, write_content_size=content_size)
    obj = compressor.compressobj(size=total if content_size else -1)
    return _zero_stream(total, obj.compress) + obj.flush()


def lz4_zeros(total: int) -> bytes:
    """An lz4 frame of ``total`` zero bytes (lz4 tops out near 255:1)."""
    compressor = lz4.frame.LZ4FrameCompressor(compression_level=0)
    head = compressor.begin(source_size=total)
    return head + _zero_stream(total, compressor.compress) + compressor.flush()


def write_segment(
    path: Path,
    chunks: Sequence[RawChunk],
    *,
    summary: bool = True,
    metadata: dict[str, str] | None = None,
    message_count: int = 0,
    loose: Sequence[tuple[int, int, int, bytes]] = (),
) -> Path:
    """A TRACE segment holding ``chunks`` as given; with an MCAP summary unless told not."""
    out = RecordBuilder()
    out.write(MAGIC)
    Header("trace", "hostile-tests").write(out)
    _schemas(out)
    _channels(out)
    meta_at = out.count
    Metadata("trace.session", metadata or session()).write(out)
    meta_len = out.count - meta_at
    for msg in loose:
        out.write(message_records([msg]))
    indexes = []
    for chunk in chunks:
        at = out.count
        Chunk(
            compression=chunk.compression,
            data=chunk.data,
            message_end_time=chunk.end_ns,
            message_start_time=chunk.start_ns,
            uncompressed_crc=chunk.crc,
            uncompressed_size=chunk.declared,
        ).write(out)
        indexes.append(
            ChunkIndex(
                chunk_length=out.count - at,
                chunk_start_offset=at,
                compression=chunk.compression,
                compressed_size=len(chunk.data),
                message_end_time=chunk.end_ns,
                message_index_length=0,
                message_index_offsets={},
                message_start_time=chunk.start_ns,
                uncompressed_size=chunk.declared,
            )
        )
    DataEnd(0).write(out)
    if not summary:
        return _finish(path, out, 0, 0)
    summary_start = out.count
    groups: list[tuple[int, int, int]] = []

    def group(opcode: int, write: Callable[[], None]) -> None:
        begin = out.count
        write()
        groups.append((opcode, begin, out.count - begin))

    group(Opcode.SCHEMA, lambda: _schemas(out))
    group(Opcode.CHANNEL, lambda: _channels(out))
    starts = [c.start_ns for c in chunks] or [0]
    ends = [c.end_ns for c in chunks] or [0]
    group(
        Opcode.STATISTICS,
        lambda: Statistics(
            attachment_count=0,
            channel_count=len(TOPICS),
            channel_message_counts={SEAL_CHANNEL: message_count},
            chunk_count=len(chunks),
            message_count=message_count,
            message_end_time=max(ends),
            message_start_time=min(starts),
            metadata_count=1,
            schema_count=len(TOPICS),
        ).write(out),
    )
    group(Opcode.CHUNK_INDEX, lambda: [i.write(out) for i in indexes])
    group(
        Opcode.METADATA_INDEX,
        lambda: MetadataIndex(meta_at, meta_len, "trace.session").write(out),
    )
    offsets_start = out.count
    for opcode, begin, length in groups:
        SummaryOffset(opcode, begin, length).write(out)
    return _finish(path, out, summary_start, offsets_start)


def _schemas(out: RecordBuilder) -> None:
    for i in range(1, len(TOPICS) + 1):
        Schema(id=i, data=b"{}", encoding="jsonschema", name=f"trace.{i}").write(out)


def _channels(out: RecordBuilder) -> None:
    for i, topic in enumerate(TOPICS, start=1):
        Channel(id=i, topic=topic, message_encoding="json", metadata={}, schema_id=i).write(out)


def _finish(path: Path, out: RecordBuilder, summary_start: int, offsets_start: int) -> Path:
    Footer(summary_start, offsets_start, 0).write(out)
    out.write(MAGIC)
    path.write_bytes(out.end())
    return path


# --- the hostile files ---------------------------------------------------------------------


def zstd_bomb(path: Path, *, declared: int | None = None, summary: bool = True) -> Path:
    """~40 KB whose one chunk inflates to 1 GiB of zeros; ``declared`` defaults to honest."""
    data = zstd_zeros(GIB, content_size=declared is None)
    size = GIB if declared is None else declared
    return write_segment(path, [RawChunk("zstd", data, size, 0, 0)], summary=summary)


def lz4_bomb(path: Path, *, declared: int | None = None, summary: bool = True) -> Path:
    """An lz4 chunk of 1 GiB of zeros (~4 MB: lz4 cannot go past ~255:1)."""
    size = GIB if declared is None else declared
    return write_segment(path, [RawChunk("lz4", lz4_zeros(GIB), size)], summary=summary)


def huge_declared(path: Path, *, summary: bool = True) -> Path:
    """A small honest-looking chunk that declares 2**62 bytes decompressed."""
    raw = message_records([(SEAL_CHANNEL, 0, 0, b"{}")])
    chunk = zstd_chunk(raw, declared=1 << 62)
    return write_segment(path, [chunk], summary=summary)


def _flood_chunk(count: int, seq: int, data: bytes) -> RawChunk:
    record = message_records([(SEAL_CHANNEL, seq, seq, data)])
    compressor = zstandard.ZstdCompressor(level=1, write_content_size=True)
    obj = compressor.compressobj(size=len(record) * count)
    parts = []
    block = record * 65536
    left = count
    while left > 0:
        take = min(left, 65536)
        parts.append(obj.compress(block[: take * len(record)]))
        left -= take
    parts.append(obj.flush())
    return RawChunk("zstd", b"".join(parts), len(record) * count, seq, seq, 0)


def flood(
    path: Path,
    *,
    total: int = 16_000_000,
    chunks: int = 1,
    summary: bool = True,
    data: bytes = b"",
) -> Path:
    """``total`` identical seal messages (empty unless ``data``) in ``chunks`` zstd chunks."""
    per = total // chunks
    built = _flood_chunk(per, 0, data)
    raw_chunks = [
        RawChunk(built.compression, built.data, built.declared, i, i) for i in range(chunks)
    ]
    return write_segment(path, raw_chunks, summary=summary, message_count=per * chunks)


def deep_json(depth: int) -> bytes:
    return b"[" * depth + b"]" * depth


def record_soup(seed: bytes) -> bytes:
    """Any bytes after a valid header and session: for fuzzing the record walker."""
    out = RecordBuilder()
    out.write(MAGIC)
    Header("trace", "soup").write(out)
    _schemas(out)
    _channels(out)
    Metadata("trace.session", session()).write(out)
    return bytes(out.end()) + seed


def record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def rewrite(
    source: Path,
    target: Path,
    change: Callable[[str, int, bytes], bytes] = lambda _topic, _cycle, data: data,
    *,
    metadata: dict[str, str] | None = None,
) -> Path:
    """Copy a segment with the plain ``mcap`` reader and Writer, passing each message's data
    through ``change(topic, sequence, data)`` (and optionally another ``trace.session``)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(source, "rb") as f, open(target, "wb") as out:
        reader = make_reader(f)
        writer = Writer(out)
        writer.start(profile=reader.get_header().profile, library="hostile-tests")
        for record in reader.iter_metadata():
            data = record.metadata
            if record.name == "trace.session" and metadata is not None:
                data = metadata
            writer.add_metadata(record.name, data)
        ids: dict[int, int] = {}
        schemas: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.id not in ids:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(
                        name=schema.name, encoding=schema.encoding, data=schema.data
                    )
                ids[channel.id] = writer.register_channel(
                    topic=channel.topic,
                    message_encoding=channel.message_encoding,
                    schema_id=schemas.get(schema.id, 0) if schema is not None else 0,
                )
            writer.add_message(
                ids[channel.id],
                message.log_time,
                change(channel.topic, message.sequence, message.data),
                message.publish_time,
                message.sequence,
            )
        writer.finish()  # type: ignore[no-untyped-call]
    return target


# --- running the CLI on them -----------------------------------------------------------------

_MEASURE = """
import json, resource, subprocess, sys, time
t = time.perf_counter()
try:
    done = subprocess.run(sys.argv[2:], capture_output=True, timeout=float(sys.argv[1]))
    code, out, err = done.returncode, done.stdout, done.stderr
except subprocess.TimeoutExpired as exc:
    code, out, err = -9, exc.stdout or b"", exc.stderr or b""
seconds = time.perf_counter() - t
rss_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
text = {"stdout": out.decode(errors="replace"), "stderr": err.decode(errors="replace")}
print(json.dumps({"code": code, "seconds": seconds, "rss_kb": rss_kb, **text}))
"""


@dataclass(frozen=True)
class Run:
    """One CLI process: exit code (-9 when it was killed at the timeout), wall seconds, peak
    RSS of that process alone, and what it printed."""

    code: int
    seconds: float
    rss_mb: float
    stdout: str
    stderr: str


def run_cli(args: Sequence[str], *, timeout_s: float = 60.0) -> Run:
    """``trace-audit ARGS`` from this checkout in a fresh process, measured by a fresh parent
    (``RUSAGE_CHILDREN`` of a process that has no other child)."""
    import json
    import os
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    cli = [sys.executable, "-c", "from trace_audit.cli import main; main()", *args]
    env = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "100"}
    done = subprocess.run(
        [sys.executable, "-c", _MEASURE, str(timeout_s), *cli],
        capture_output=True,
        env=env,
        timeout=timeout_s + 30,
        check=True,
    )
    got = json.loads(done.stdout)
    return Run(got["code"], got["seconds"], got["rss_kb"] / 1024, got["stdout"], got["stderr"])
