"""Frames cut from a byte stream however it arrives, and messages checked field by field."""

from __future__ import annotations

import struct
from typing import Any

import orjson
import pytest
from hypothesis import given
from hypothesis import strategies as st

from trace_runtime.errors import WireProtocolError
from trace_runtime.recorder.protocol import (
    FrameReader,
    Oversized,
    encode_frame,
    message_kind,
    parse_cycle,
    parse_message,
)

_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**63), 2**63 - 1) | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner),
    max_leaves=20,
)


@given(
    st.lists(st.dictionaries(st.text(max_size=8), _JSON, max_size=5), max_size=6),
    st.lists(st.integers(1, 50), min_size=1, max_size=20),
)
def test_frames_come_back_whole_however_the_stream_is_cut(
    messages: list[dict[str, Any]], cuts: list[int]
) -> None:
    stream = b"".join(encode_frame(m) for m in messages)
    reader = FrameReader()
    got: list[Any] = []
    position, turn = 0, 0
    while position < len(stream):
        step = cuts[turn % len(cuts)]
        got += reader.feed(stream[position : position + step])
        position, turn = position + step, turn + 1
    assert [orjson.loads(f) for f in got if isinstance(f, bytes)] == messages
    assert reader.pending == 0


def test_an_oversized_frame_is_skipped_without_being_kept() -> None:
    reader = FrameReader(max_frame_bytes=20)
    out = reader.feed(struct.pack(">I", 1000) + b"x" * 400)
    assert out == [Oversized(1000)]
    assert reader.pending == 600  # still to skip, nothing held
    assert reader.feed(b"x" * 600 + encode_frame({"kind": "bye"})) == [b'{"kind":"bye"}']


@pytest.mark.parametrize(
    ("body", "needle"),
    [(b"nope", "not JSON"), (b"3", "JSON object"), (b'{"kind": "x"}', "unknown kind")],
)
def test_a_frame_that_is_not_a_message_says_why(body: bytes, needle: str) -> None:
    with pytest.raises(WireProtocolError, match=needle):
        message_kind(parse_message(body))


@pytest.mark.parametrize(
    ("fields", "needle"),
    [
        ({}, "t_ns"),
        ({"t_ns": -1}, "t_ns"),
        ({"t_ns": True}, "t_ns"),
        ({"t_ns": 1, "dropped": 10**7}, "dropped"),
        ({"t_ns": 1, "action": []}, "action"),
        ({"t_ns": 1, "sensors": [{"topic": "/sensors/a"}]}, "data is missing"),
        ({"t_ns": 1, "sensors": [{"topic": 3, "data": 1}]}, "topic"),
        ({"t_ns": 1, "sensors": [{}] * 1025}, "at most 1024"),
    ],
)
def test_a_bad_cycle_message_names_its_field(fields: dict[str, Any], needle: str) -> None:
    with pytest.raises(WireProtocolError, match=needle):
        parse_cycle({"kind": "cycle", **fields})
