"""Metrics' byte-level shortcut: a perception message is walked for external-recording refs
unless its bytes show it cannot hold one. The shortcut must never skip a message that has
a ``recording`` key, however the key is spelled in JSON."""

from __future__ import annotations

from typing import Any

import orjson
from hypothesis import given
from hypothesis import strategies as st

from trace_audit.metrics.scan import _may_cite_recording

_KEYS = st.sampled_from(["recording", "ref", "entities", "evidence", "topic", "record", "x"])
_JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**53), 2**53) | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_KEYS, inner, max_size=4),
    max_leaves=20,
)


def _has_recording_key(value: Any) -> bool:
    if isinstance(value, dict):
        return "recording" in value or any(_has_recording_key(v) for v in value.values())
    if isinstance(value, list):
        return any(_has_recording_key(v) for v in value)
    return False


def _escaped(data: bytes, at: int) -> bytes:
    """The same JSON with one letter of every ``recording`` key written as a \\u escape."""
    letter = "recording"[at]
    return data.replace(
        b'"recording"',
        b'"'
        + "recording"[:at].encode()
        + f"\\u{ord(letter):04x}".encode()
        + "recording"[at + 1 :].encode()
        + b'"',
    )


@given(_JSON, st.integers(min_value=0, max_value=8))
def test_a_message_with_a_recording_key_is_always_walked(value: Any, at: int) -> None:
    for data in (orjson.dumps(value), _escaped(orjson.dumps(value), at)):
        assert orjson.loads(data) == value
        if _has_recording_key(value):
            assert _may_cite_recording(data)


def test_plain_messages_are_skipped_and_summaries_walked() -> None:
    assert not _may_cite_recording(b'{"entities":[{"evidence":[{"ref":{"topic":"/a"}}]}]}')
    assert _may_cite_recording(b'{"entities":[{"evidence":[{"ref":{"recording":"a"}}]}]}')
    assert _may_cite_recording(None)  # a warm summary cycle: its parsed layer is walked
