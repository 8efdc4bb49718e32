"""Fuzzing the reader with its limits on: whatever the bytes, reading a file ends in a clean
read or a ``LogReadError`` (or a subclass), never another exception, and in bounded time.

Two sources of bytes: mutations of a small real segment (flipped, cut, inserted and
repeated bytes), and record soup (a valid header and ``trace.session`` followed by random
records, some of them chunks with random compression and declared sizes).
"""

from __future__ import annotations

import struct
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.trace_runtime import hostile
from tests.trace_runtime.conftest import write_log
from trace_runtime.errors import LogReadError
from trace_runtime.read_limits import ReadLimits
from trace_runtime.reading.logset import open_log
from trace_runtime.reading.reader import Segment

TIGHT = ReadLimits(max_chunk_bytes=1 << 20, small_chunk_bytes=4096, max_record_bytes=1 << 20)
MAX_SECONDS = 5.0


@pytest.fixture(scope="module")
def real_segment(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("fuzz") / "small.mcap"
    write_log(path, 4)
    return path.read_bytes()


def _read_everything(data: bytes, limits: ReadLimits | None = None) -> None:
    """Every read an investigator's command makes, on ``data`` as a segment file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.mcap"
        path.write_bytes(data)
        started = time.perf_counter()
        try:
            segment = Segment(path, limits) if limits else open_log(path).segments[0]
            _ = segment.info, segment.metadata, segment.chunks()
            for cycle in segment.iter_cycles():
                for topic in cycle.payloads:
                    cycle.layer(topic)
                _ = cycle.seal, cycle.action
            list(segment.iter_cycles(reverse=True))
            segment.cycle_at(segment.end_ns)
        except LogReadError:
            pass
        assert time.perf_counter() - started < MAX_SECONDS


FUZZ = settings(
    max_examples=150,
    deadline=None,  # the time bound is asserted per read; CI machines are noisy
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@FUZZ
@given(
    flips=st.lists(st.tuples(st.integers(0, 1 << 20), st.integers(0, 255)), max_size=8),
    cut=st.none() | st.integers(0, 1 << 20),
    insert=st.none() | st.tuples(st.integers(0, 1 << 20), st.binary(min_size=1, max_size=64)),
    tight=st.booleans(),
)
def test_a_mutated_segment_reads_or_raises_log_read_error(
    real_segment: bytes,
    flips: list[tuple[int, int]],
    cut: int | None,
    insert: tuple[int, bytes] | None,
    tight: bool,
) -> None:
    data = bytearray(real_segment)
    for at, value in flips:
        data[at % len(data)] = value
    if insert is not None:
        at = insert[0] % len(data)
        data[at:at] = insert[1]
    if cut is not None:
        del data[cut % len(data) :]
    _read_everything(bytes(data), TIGHT if tight else None)


_PAYLOADS = st.sampled_from(
    [b"{}", b"", b"[", b'{"cycle":1}', hostile.deep_json(2000)]
) | st.binary(max_size=8)
_OPCODES = st.sampled_from([1, 2, 3, 4, 5, 6, 8, 10, 11, 12, 13, 14, 15, 0x80, 0])


@st.composite
def _records(draw: st.DrawFn) -> bytes:
    parts = []
    for _ in range(draw(st.integers(0, 12))):
        if draw(st.booleans()):  # a chunk of messages, often honest enough to be read
            raw = hostile.message_records(
                [
                    (draw(st.integers(1, 7)), 0, draw(st.integers(0, 5)), draw(_PAYLOADS))
                    for _ in range(draw(st.integers(1, 6)))
                ]
            )
            declared = st.none() | st.integers(0, (1 << 64) - 1)
            chunk = hostile.zstd_chunk(raw, declared=draw(declared))
            crc = draw(st.sampled_from([0, chunk.crc]))
            body = struct.pack("<QQQI", 0, 0, chunk.declared, crc)
            body += struct.pack("<I", 4) + b"zstd" + struct.pack("<Q", len(chunk.data)) + chunk.data
            parts.append(hostile.record(6, body))
        else:
            parts.append(hostile.record(draw(_OPCODES), draw(st.binary(max_size=48))))
    if draw(st.booleans()):
        # a length field that lies (past the end, or huge)
        parts.append(struct.pack("<BQ", draw(_OPCODES), draw(st.integers(0, (1 << 64) - 1))))
    return b"".join(parts)


@FUZZ
@given(soup=_records(), tail=st.binary(max_size=64), tight=st.booleans())
def test_record_soup_reads_or_raises_log_read_error(soup: bytes, tail: bytes, tight: bool) -> None:
    data = hostile.record_soup(soup + tail)
    _read_everything(data, TIGHT if tight else None)
    _read_everything(data + hostile.MAGIC, TIGHT if tight else None)
