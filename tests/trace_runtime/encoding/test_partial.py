"""Each partial decode is the full one restricted to its fields, or declines.

For random valid records (the models' strategies of ``test_records``), every shape gives
exactly the full parse's values for its keys, of the same JSON types; for damaged bytes it
gives those values or nothing, and never succeeds where orjson refuses the message, but for
the one case the metrics scan closes itself (a skipped number past a double's range).
"""

from __future__ import annotations

import types
import typing
from typing import Any

import msgspec
import orjson
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from tests.trace_runtime.test_records import actions, beliefs, executions, perceptions
from trace_runtime.encoding.codec import encode_layer
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.encoding.partial import (
    DECISION_FIELDS,
    INDEX_ACTION,
    INDEX_BELIEF,
    INDEX_PERCEPTION,
    METRICS_ACTION,
    METRICS_BELIEF,
    METRICS_PERCEPTION,
    RULES_ACTION,
    RULES_BELIEF,
    RULES_EXECUTION,
    RULES_PERCEPTION,
    SEAL_FIELDS,
    DecisionFields,
    IndexAction,
    IndexBelief,
    IndexPerception,
    MetricsAction,
    MetricsBelief,
    MetricsPerception,
    RulesAction,
    RulesBelief,
    RulesExecution,
    RulesPerception,
    Shape,
    decision_fields,
    read_layer,
)
from trace_runtime.encoding.seal_check import _parse_seal, _parse_seal_in_full
from trace_runtime.errors import PayloadError
from trace_runtime.records import (
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_PERCEPTION,
    Action,
    ActionMessage,
    Belief,
    Perception,
)
from trace_runtime.testing import synthetic_cycle

SHAPES: dict[str, tuple[Shape[Any], type]] = {
    TOPIC_PERCEPTION: (METRICS_PERCEPTION, Perception),
    TOPIC_BELIEF: (METRICS_BELIEF, Belief),
    TOPIC_ACTION: (METRICS_ACTION, Action),
}


def project(kind: Any, value: Any) -> Any:
    """``value`` (orjson's parse) restricted to what the shape type ``kind`` declares."""
    origin = typing.get_origin(kind)
    if origin is typing.Annotated:
        return project(typing.get_args(kind)[0], value)
    if origin in (typing.Union, types.UnionType):
        if value is None:
            return None
        inner = [a for a in typing.get_args(kind) if a is not type(None)]
        if len(inner) > 1:  # a union of scalars (a number, a text, a flag): as parsed
            return value
        return project(inner[0], value)
    if origin is list:
        (inner,) = typing.get_args(kind)
        return [project(inner, v) for v in value]
    if typing.is_typeddict(kind):
        hints = typing.get_type_hints(kind, include_extras=True)
        return {k: project(hints[k], v) for k, v in value.items() if k in hints}
    return value


def typed(value: Any) -> bytes:
    """The value as JSON text: equal only when equal with the same JSON types (1 is not
    1.0 nor true), keys in the same order."""
    return orjson.dumps(value)


_KINDS: dict[Shape[Any], type] = {
    METRICS_ACTION: MetricsAction,
    METRICS_BELIEF: MetricsBelief,
    METRICS_PERCEPTION: MetricsPerception,
    RULES_PERCEPTION: RulesPerception,
    RULES_BELIEF: RulesBelief,
    RULES_ACTION: RulesAction,
    RULES_EXECUTION: RulesExecution,
    INDEX_ACTION: IndexAction,
    INDEX_BELIEF: IndexBelief,
    INDEX_PERCEPTION: IndexPerception,
}


def check_shape(shape: Shape[Any], data: bytes) -> None:
    """The shape gives the full parse's fields, or declines (None)."""
    fast = shape.decode(data)
    try:
        full = orjson.loads(data)
    except orjson.JSONDecodeError as err:
        # orjson refuses it: so must the fast path, but for a skipped number out of range,
        # which the metrics scan re-parses in full where the seal does not vouch for it
        assert fast is None or "infinity" in str(err), (data, fast)
        return
    if fast is not None:
        assert typed(fast) == typed(project(_KINDS[shape], full))


layer_records = st.one_of(
    st.tuples(st.just(TOPIC_PERCEPTION), perceptions),
    st.tuples(st.just(TOPIC_BELIEF), beliefs),
    st.tuples(st.just(TOPIC_ACTION), actions),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(record=layer_records, cycle=st.integers(0, 2**40), t_ns=st.integers(0, 2**62))
def test_every_valid_record_decodes_to_the_full_parse_of_its_fields(
    record: tuple[str, Any], cycle: int, t_ns: int
) -> None:
    topic, value = record
    shape, _model = SHAPES[topic]
    data = encode_layer(cycle, t_ns, value)
    fast = shape.decode(data)
    assert fast is not None, data  # a valid record never needs the full parse
    assert typed(fast) == typed(project(_KINDS[shape], orjson.loads(data)))


_RULES = st.one_of(
    st.tuples(st.just(RULES_PERCEPTION), perceptions),
    st.tuples(st.just(RULES_BELIEF), beliefs),
    st.tuples(st.just(RULES_ACTION), actions),
    st.tuples(st.just(RULES_EXECUTION), executions),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(record=_RULES, cycle=st.integers(0, 2**40), t_ns=st.integers(0, 2**62))
def test_every_valid_record_gives_the_rules_the_full_parse_of_their_fields(
    record: tuple[Shape[Any], Any], cycle: int, t_ns: int
) -> None:
    shape, value = record
    data = encode_layer(cycle, t_ns, value)
    fast = shape.decode(data)
    assert fast is not None, data  # a valid record never needs the full parse
    assert typed(fast) == typed(project(_KINDS[shape], orjson.loads(data)))
    check_shape(shape, data)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    record=layer_records,
    edits=st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), min_size=1, max_size=3),
)
def test_damaged_bytes_decode_to_the_full_parse_or_not_at_all(
    record: tuple[str, Any], edits: list[tuple[int, int]]
) -> None:
    topic, value = record
    data = bytearray(encode_layer(7, 700, value))
    for at, byte in edits:
        data[at % len(data)] = byte
    check_shape(SHAPES[topic][0], bytes(data))


JSON_TOKENS = st.sampled_from(
    [
        b"1e400",
        b"-1e400",
        b"18446744073709551616",
        b"9223372036854775808",
        b"-9223372036854775809",
        b'"\\ud800"',
        b'"\xff"',
        b'"\xc3\xa9"',
        b"1.0",
        b"true",
        b"null",
        b"[]",
        b"{}",
        b'"x"',
        b"0",
        b"[1]",
        b'[{"a":1}]',
        b"[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]",
    ]
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(record=layer_records, token=JSON_TOKENS, nth=st.integers(0, 200))
def test_a_value_swapped_for_an_odd_one_decodes_as_the_full_parse(
    record: tuple[str, Any], token: bytes, nth: int
) -> None:
    """Any value of the message (after its nth ``:``) replaced by an awkward token: a number
    past orjson's range, an invalid string, another type, deep nesting."""
    topic, value = record
    data = encode_layer(3, 300, value)
    colons = [i for i, b in enumerate(data) if b == ord(":")]
    assume(colons)
    at = colons[nth % len(colons)] + 1
    end = at
    try:
        _, end = _value_end(data, at)
    except ValueError:
        assume(False)
    check_shape(SHAPES[topic][0], data[:at] + token + data[end:])


def _value_end(data: bytes, at: int) -> tuple[int, int]:
    """Where the JSON value starting at ``at`` ends (a small scanner for the test)."""
    depth, i, in_str = 0, at, False
    while i < len(data):
        c = data[i : i + 1]
        if in_str:
            if c == b"\\":
                i += 1
            elif c == b'"':
                in_str = False
                if depth == 0:
                    return at, i + 1
        elif c == b'"':
            in_str = True
        elif c in b"[{":
            depth += 1
        elif c in b"]}":
            if depth == 0:
                return at, i
            depth -= 1
            if depth == 0:
                return at, i + 1
        elif c == b"," and depth == 0:
            return at, i
        i += 1
    raise ValueError("no end")


def test_the_shapes_of_a_synthetic_cycle_hold_only_what_metrics_read() -> None:
    perception, belief, action, _execution = synthetic_cycle(5)
    fast = METRICS_ACTION.decode(encode_layer(5, 500, action))
    assert fast is not None
    assert set(fast) == {
        "command",
        "alternatives",
        "rationale",
        "counterfactuals",
        "counterfactuals_none_applicable",
    }
    assert all(alt == {} for alt in fast["alternatives"])
    assert fast["rationale"]["factors"][0] == {"node": "ped_1.distance"}
    node = METRICS_BELIEF.decode(encode_layer(5, 500, belief))["nodes"][0]  # type: ignore[index]
    assert node == {"id": "ped_1", "kind": "entity", "entity": "ped_1"}
    entity = METRICS_PERCEPTION.decode(encode_layer(5, 500, perception))["entities"][0]  # type: ignore[index]
    assert set(entity) == {"id", "evidence"}


@pytest.mark.parametrize(
    "data",
    [b"", b'{"command": ', b"[1, 2]", b'{"command": 3}', b'{"rationale": null}', b'{"x": "\xff"}'],
)
def test_read_layer_gives_the_full_parse_or_its_error_where_the_shape_declines(
    data: bytes,
) -> None:
    cycle = Cycle(1, 100, {TOPIC_ACTION: data}, segment="s.mcap")
    try:
        expected = cycle.layer(TOPIC_ACTION)
    except PayloadError as err:
        with pytest.raises(PayloadError) as caught:
            read_layer(cycle, METRICS_ACTION)
        assert str(caught.value) == str(err)
        return
    assert read_layer(cycle, METRICS_ACTION) == expected


def test_read_layer_of_a_summary_cycle_or_a_missing_layer() -> None:
    summary = {TOPIC_ACTION: {"command": "STOP", "tree": {"nodes": []}}}
    cycle = Cycle(1, 100, {}, segment="s.mcap", summary=summary)
    assert read_layer(cycle, METRICS_ACTION) is summary[TOPIC_ACTION]
    assert read_layer(Cycle(1, 100, {}), METRICS_ACTION) is None


# --- decision fields: a Struct, pinned to the model ----------------------------------------


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(action=actions, cycle=st.integers(0, 2**40), t_ns=st.integers(0, 2**62))
def test_decision_fields_are_the_action_models_fields(
    action: Action, cycle: int, t_ns: int
) -> None:
    data = encode_layer(cycle, t_ns, action, Action)
    fields = DECISION_FIELDS.decode(data)
    model = ActionMessage.model_validate_json(data)
    assert isinstance(fields, DecisionFields)
    assert (fields.cycle, fields.t_ns, fields.command) == (model.cycle, model.t_ns, model.command)
    assert typed(fields.score) == typed(model.score)
    assert fields.rationale.text == model.rationale.text
    assert fields.truncated == model.rationale.truncated
    assert len(fields.alternatives) == len(model.alternatives)
    assert len(fields.counterfactuals) == len(model.counterfactuals)
    assert fields.counterfactuals_none_applicable == model.counterfactuals_none_applicable
    assert [typed(msgspec.to_builtins(f)) for f in fields.factors] == [
        typed({"node": f.node, "value": f.value, "name": f.name, "unit": f.unit})
        for f in model.rationale.factors
    ]


def test_decision_fields_of_an_action_the_shape_declines_come_from_the_model() -> None:
    _p, _b, action, _e = synthetic_cycle(2)
    data = encode_layer(2, 200, action, Action)
    assert b'"truncated":false' in data
    lax = data.replace(b'"truncated":false', b'"truncated":1')  # the model's lax bool
    assert DECISION_FIELDS.decode(lax) is None
    fields = decision_fields(Cycle(2, 200, {TOPIC_ACTION: lax}, segment="s.mcap"))
    assert fields is not None and fields.truncated is True
    assert fields.command == action.command and fields.cycle == 2
    broken = Cycle(3, 300, {TOPIC_ACTION: b'{"cycle":3,"t_ns":300}'}, segment="s.mcap")
    with pytest.raises(PayloadError, match="not a valid ActionMessage"):
        decision_fields(broken)
    assert decision_fields(Cycle(4, 400, {})) is None


# --- the seal check's seal shape ----------------------------------------------------------

_HEX = st.text("0123456789abcdef", min_size=64, max_size=64)
_TOPICS = st.sampled_from(
    ["/trace/perception", "/trace/belief", "/trace/action", "/trace/execution", "/trace/x"]
)
seals = st.fixed_dictionaries(
    {
        "cycle": st.integers(0, 2**63 - 1),
        "t_ns": st.integers(0, 2**63 - 1),
        "digests": st.dictionaries(_TOPICS, _HEX, max_size=5),
        "prev": _HEX,
    },
    optional={
        "dropped": st.integers(0, 2**40),
        "sensors": st.fixed_dictionaries({"count": st.integers(0, 2**40), "digest": _HEX}),
    },
)


def check_seal(data: bytes) -> None:
    """The seal's shape gives exactly the full parse's fields (same types, same key order),
    or declines; it never accepts a seal the full parse refuses."""
    fast = SEAL_FIELDS.decode(data)
    full = _parse_seal_in_full(data)
    if fast is None:
        return
    cover = None if fast.sensors is None else (fast.sensors.count, fast.sensors.digest)
    got = (fast.cycle, fast.t_ns, fast.digests, fast.prev, fast.dropped, cover)
    assert full is not None, (data, got)
    assert typed(list(got)) == typed(list(full)), data
    assert list(got[2]) == list(full[2])  # the digests' order: the order problems are named in


@settings(max_examples=300, deadline=None)
@given(seal=seals)
def test_every_valid_seal_decodes_to_the_full_parse(seal: dict[str, Any]) -> None:
    data = orjson.dumps(seal)
    fast = SEAL_FIELDS.decode(data)
    assert fast is not None, data  # a valid seal never needs the full parse
    check_seal(data)
    assert _parse_seal(data) == _parse_seal_in_full(data)


@settings(max_examples=400, deadline=None)
@given(
    seal=seals,
    edits=st.lists(st.tuples(st.integers(0, 1_000), st.integers(0, 255)), min_size=1, max_size=3),
)
def test_a_damaged_seal_decodes_to_the_full_parse_or_not_at_all(
    seal: dict[str, Any], edits: list[tuple[int, int]]
) -> None:
    data = bytearray(orjson.dumps(seal))
    for at, byte in edits:
        data[at % len(data)] = byte
    check_seal(bytes(data))
    assert _parse_seal(bytes(data)) == _parse_seal_in_full(bytes(data))


@settings(max_examples=400, deadline=None)
@given(seal=seals, token=JSON_TOKENS, nth=st.integers(0, 20))
def test_a_seal_value_swapped_for_an_odd_one_decodes_as_the_full_parse(
    seal: dict[str, Any], token: bytes, nth: int
) -> None:
    data = orjson.dumps(seal)
    colons = [i for i, b in enumerate(data) if b == ord(":")]
    at = colons[nth % len(colons)] + 1
    _, end = _value_end(data, at)
    swapped = data[:at] + token + data[end:]
    check_seal(swapped)
    assert _parse_seal(swapped) == _parse_seal_in_full(swapped)


@pytest.mark.parametrize(
    "data",
    [
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","dropped":0,"extra":1e400}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","note":"x"}',
        b'{"cycle":1,"cycle":2,"t_ns":2,"digests":{"/a":"1","/b":"2","/a":"3"},"prev":"p"}',
        b'{"cycle":true,"t_ns":2,"digests":{},"prev":"p"}',
        b'{"cycle":1.0,"t_ns":2,"digests":{},"prev":"p"}',
        b'{"cycle":1e2,"t_ns":2,"digests":{},"prev":"p"}',
        b'{"cycle":18446744073709551615,"t_ns":2,"digests":{},"prev":"p"}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","dropped":null}',
        b'{"cycle":1,"t_ns":2,"digests":{"/a":null},"prev":"p"}',
        b'{"cycle":1,"t_ns":2,"prev":"p"}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"\xff"}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"\\ud800"}',
        b'[1,2,{},"p",0]',
        b' {"cycle":1,"t_ns":2,"digests":{},"prev":"p"} ',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":null}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":{"count":1}}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":{"count":1,"digest":"d","x":0}}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":{"count":true,"digest":"d"}}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":{"count":1.0,"digest":"d"}}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":[1,"d"]}',
        b'{"cycle":1,"t_ns":2,"digests":{},"prev":"p","sensors":{"count":1,"digest":"d","count":2}}',
    ],
)
def test_odd_seals_read_as_the_full_parse_reads_them(data: bytes) -> None:
    check_seal(data)
    assert _parse_seal(data) == _parse_seal_in_full(data)


_INDEX = st.one_of(
    st.tuples(st.just(INDEX_PERCEPTION), perceptions),
    st.tuples(st.just(INDEX_BELIEF), beliefs),
    st.tuples(st.just(INDEX_ACTION), actions),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(record=_INDEX, cycle=st.integers(0, 2**40), t_ns=st.integers(0, 2**62))
def test_every_valid_record_gives_the_index_the_full_parse_of_its_fields(
    record: tuple[Shape[Any], Any], cycle: int, t_ns: int
) -> None:
    shape, value = record
    data = encode_layer(cycle, t_ns, value)
    fast = shape.decode(data)
    assert fast is not None, data  # a valid record never needs the full parse
    assert typed(fast) == typed(project(_KINDS[shape], orjson.loads(data)))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    record=_INDEX,
    edits=st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), min_size=1, max_size=3),
)
def test_damaged_bytes_give_the_index_the_full_parse_or_nothing(
    record: tuple[Shape[Any], Any], edits: list[tuple[int, int]]
) -> None:
    shape, value = record
    data = bytearray(encode_layer(7, 700, value))
    for at, byte in edits:
        data[at % len(data)] = byte
    check_shape(shape, bytes(data))
