"""``codec.validate_parsed`` (doctor's schema check of every message) gives pydantic's verdict:
the msgspec mirror may only make it faster, never accept what pydantic refuses."""

from __future__ import annotations

from typing import Any

import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from tests.trace_runtime.test_records import _bad_values, _layer_records, _paths, _replace
from trace_runtime.encoding.codec import _mirror_or_none, validate_parsed
from trace_runtime.errors import RecordError
from trace_runtime.record_model import validate_record
from trace_runtime.records import (
    LAYER_MODELS,
    MESSAGE_MODELS,
    TOPIC_CHECKPOINT,
    TOPIC_SEAL,
)

_MESSAGE_OF = {LAYER_MODELS[topic]: MESSAGE_MODELS[topic] for topic in LAYER_MODELS}
_HEX = st.text("0123456789abcdef", min_size=64, max_size=64)
_seals = st.fixed_dictionaries(
    {
        "cycle": st.integers(0, 2**63 - 1),
        "t_ns": st.integers(0, 2**63 - 1),
        "digests": st.dictionaries(st.sampled_from(list(LAYER_MODELS)), _HEX),
        "prev": _HEX,
        "dropped": st.integers(0, 2**32),
    },
    optional={"sensors": st.fixed_dictionaries({"count": st.integers(0, 99), "digest": _HEX})},
)


def _verdict(model: Any, value: Any) -> str | None:
    """pydantic's verdict on ``value``: None when valid, else ``RecordError``'s message."""
    try:
        validate_record(model, value)
    except RecordError as err:
        return str(err)
    return None


def _ours(model: Any, value: Any) -> str | None:
    try:
        validate_parsed(model, value)
    except RecordError as err:
        return str(err)
    return None


@settings(max_examples=400, deadline=None)
@given(record=_layer_records, seal=_seals, data=st.data())
def test_a_spoiled_message_gets_pydantics_verdict_and_message(
    record: Any, seal: dict[str, Any], data: st.DataObject
) -> None:
    if data.draw(st.booleans()):
        model: Any = MESSAGE_MODELS[TOPIC_SEAL]
        plain: Any = seal
    else:
        model = _MESSAGE_OF[type(record)]
        stamp = {
            "cycle": data.draw(st.integers(0, 2**40)),
            "t_ns": data.draw(st.integers(0, 2**63 - 1)),
        }
        plain = {**stamp, **record.model_dump(by_alias=True, mode="json")}
    plain = orjson.loads(orjson.dumps(plain))  # what a reader parses from the bytes
    spoiled = plain
    if data.draw(st.booleans()):
        path = data.draw(st.sampled_from(_paths(plain)[1:]))
        spoiled = _replace(plain, path, data.draw(_bad_values))
    if data.draw(st.booleans()):
        spoiled = {**spoiled, data.draw(st.sampled_from(["extra", "cycle", "t_ns"])): -1}
    assert _ours(model, spoiled) == _verdict(model, spoiled)


def test_the_messages_of_a_log_take_the_mirror_and_a_checkpoint_takes_pydantic() -> None:
    """The fast path is there for the layers and the seal (what doctor checks 5 times a
    cycle); a model whose constraint the mirror cannot reproduce is pydantic's alone."""
    for topic in (*LAYER_MODELS, TOPIC_SEAL):
        assert _mirror_or_none(MESSAGE_MODELS[topic]) is not None
    assert _mirror_or_none(MESSAGE_MODELS[TOPIC_CHECKPOINT]) is None
    with pytest.raises(RecordError, match="invalid Checkpoint"):
        validate_parsed(MESSAGE_MODELS[TOPIC_CHECKPOINT], {"cycle": 1})
    with pytest.raises(ValidationError):
        MESSAGE_MODELS[TOPIC_CHECKPOINT].model_validate({"cycle": 1})
