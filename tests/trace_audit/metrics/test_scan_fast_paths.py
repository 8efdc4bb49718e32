"""Metrics' byte-level shortcut: a perception message is walked for external-recording refs
unless its bytes show it cannot hold one. The shortcut must never skip a message that has
a ``recording`` key holding a string (what the tally counts), however the key is spelled in
JSON; a message whose every ``recording`` is ``null`` may be skipped."""

from __future__ import annotations

import json
from typing import Any

import orjson
from hypothesis import given
from hypothesis import strategies as st

from trace_audit.metrics.scan import _may_cite_recording

_KEYS = st.sampled_from(["recording", "ref", "entities", "evidence", "topic", "record", "x"])
_JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**53), 2**53)
    | st.text(max_size=12)
    | st.sampled_from(["recording", "null", '"recording":null', "a recording"]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_KEYS, inner, max_size=4),
    max_leaves=20,
)


def _has_recording_string(value: Any) -> bool:
    if isinstance(value, dict):
        return isinstance(value.get("recording"), str) or any(
            _has_recording_string(v) for v in value.values()
        )
    if isinstance(value, list):
        return any(_has_recording_string(v) for v in value)
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


def _spellings(value: Any, at: int) -> list[bytes]:
    """The value as canonical JSON, with a letter of ``recording`` escaped, and spaced out."""
    canonical = orjson.dumps(value)
    spaced = json.dumps(value, separators=(" , ", " : "), ensure_ascii=False).encode()
    return [canonical, _escaped(canonical, at), spaced]


@given(_JSON, st.integers(min_value=0, max_value=8))
def test_a_message_with_a_recording_string_is_always_walked(value: Any, at: int) -> None:
    for data in _spellings(value, at):
        assert orjson.loads(data) == value
        if _has_recording_string(value):
            assert _may_cite_recording(data)


def test_plain_messages_are_skipped_and_summaries_walked() -> None:
    assert not _may_cite_recording(b'{"entities":[{"evidence":[{"ref":{"topic":"/a"}}]}]}')
    assert _may_cite_recording(b'{"entities":[{"evidence":[{"ref":{"recording":"a"}}]}]}')
    assert _may_cite_recording(None)  # a warm summary cycle: its parsed layer is walked


def test_refs_naming_no_recording_are_skipped() -> None:
    """A writer that gives every ref ``"recording":null`` (the simulator does) is not
    walked; one string among the nulls, or a null spelled otherwise, is."""
    null = b'{"ref":{"topic":"/a","recording":null}}'
    assert not _may_cite_recording(b'{"entities":[{"evidence":[%s,%s]}]}' % (null, null))
    assert _may_cite_recording(
        b'{"entities":[{"evidence":[%s,{"ref":{"recording":"bag"}}]}]}' % null
    )
    assert _may_cite_recording(b'{"ref":{"recording": null}}')
    assert _may_cite_recording(b'{"ref":{"recording":"null"}}')
