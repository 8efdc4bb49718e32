"""Records: validation at the call site, and lossless round trips through a real MCAP log."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from trace_runtime import (
    Action,
    AuditLogger,
    Belief,
    BeliefEdge,
    BeliefNode,
    Entity,
    Evidence,
    EvidenceRef,
    Execution,
    Factor,
    LoggerConfig,
    Motion,
    Perception,
    Pose,
    Rationale,
    RecordError,
    open_log,
)
from trace_runtime.encoding.codec import _mirror, check_layer, encode_layer, layer_message
from trace_runtime.records import (
    Alternative,
    ComplianceCheck,
    Counterfactual,
    DecisionTree,
    PerceptionMessage,
    Region,
    TreeEdge,
    TreeNode,
)
from trace_runtime.testing import CaptureLogger

names = st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), min_size=1, max_size=12)
finite = st.floats(allow_nan=False, allow_infinity=False, width=64) | st.sampled_from(
    [1e21, -1.5e300, 1e16, 9.999e15, 1e-7, -0.0, 0.30000000000000004]  # exponent spellings
)
unit = st.floats(min_value=0.0, max_value=1.0)
scalars = st.one_of(finite, st.integers(-(2**53), 2**53), st.booleans(), names)

refs = st.builds(
    EvidenceRef,
    topic=names.map(lambda s: "/sensors/" + s),
    log_time_ns=st.integers(0, 2**63 - 1),
    sequence=st.none() | st.integers(0, 2**32 - 1),
    digest=st.none() | st.text("0123456789abcdef", min_size=64, max_size=64),
)
evidence = st.builds(
    Evidence,
    sensor=names,
    weight=unit,
    region=st.none()
    | st.builds(
        Region,
        kind=st.sampled_from(["beams", "box", "cone", "pixels"]),
        values=st.lists(finite, max_size=4),
    ),
    ref=st.none() | refs,
)
entities = st.builds(
    Entity,
    id=names,
    cls=names,
    pose=st.builds(
        Pose,
        position=st.tuples(finite, finite, finite),
        orientation=st.tuples(finite, finite, finite, finite),
    ),
    velocity=st.none() | st.tuples(finite, finite, finite),
    confidence=st.dictionaries(names, unit, max_size=3),
    evidence=st.lists(evidence, max_size=3),
)
perceptions = st.builds(
    Perception,
    entities=st.lists(entities, max_size=3),
    sensors_used=st.lists(names, max_size=2),
    sensors_unavailable=st.lists(names, max_size=2),
)
beliefs = st.builds(
    Belief,
    nodes=st.lists(
        st.builds(
            BeliefNode,
            id=names,
            kind=st.sampled_from(["entity", "state"]),
            label=st.text(max_size=8),
            p=unit,
            value=st.none() | scalars,
            unit=st.none() | names,
            entity=st.none() | names,
        ),
        max_size=4,
    ),
    edges=st.lists(
        st.builds(BeliefEdge, parent=names, child=names, p=unit, rule=names), max_size=4
    ),
)
actions = st.builds(
    Action,
    command=names,
    parameters=st.dictionaries(names, finite, max_size=2),
    score=st.none() | finite,
    alternatives=st.lists(
        st.builds(Alternative, command=names, score=finite, rejected_because=st.text(max_size=20)),
        max_size=3,
    ),
    rationale=st.builds(
        Rationale,
        text=st.text(max_size=40),
        factors=st.lists(
            st.builds(
                Factor, node=names, name=st.text(max_size=8), value=scalars, unit=st.none() | names
            ),
            max_size=3,
        ),
        truncated=st.booleans(),
    ),
    counterfactuals=st.lists(
        st.builds(
            Counterfactual,
            factor=names,
            comparison=st.sampled_from(["<", "<=", ">", ">=", "==", "!="]),
            threshold=scalars,
            would_select=names,
        ),
        max_size=3,
    ),
    counterfactuals_none_applicable=st.booleans(),
    tree=st.none()
    | st.builds(
        DecisionTree,
        nodes=st.lists(
            st.builds(
                TreeNode,
                id=names,
                label=st.text(max_size=8),
                test=st.none() | names,
                command=st.none() | names,
            ),
            max_size=3,
        ),
        edges=st.lists(
            st.builds(TreeEdge, parent=names, child=names, label=st.text(max_size=5)), max_size=3
        ),
        taken_path=st.lists(names, max_size=3),
    ),
)
executions = st.builds(
    Execution,
    intended=st.builds(Motion, linear=finite, angular=finite),
    actual=st.builds(Motion, linear=finite, angular=finite),
    deviation=st.floats(min_value=0.0, allow_nan=False, allow_infinity=False),
    checks=st.lists(
        st.builds(
            ComplianceCheck,
            rule=names,
            passed=st.booleans(),
            value=st.none() | finite,
            limit=st.none() | finite,
            detail=st.text(max_size=10),
        ),
        max_size=2,
    ),
    flags=st.lists(names, max_size=3),
)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    cycles=st.lists(st.tuples(perceptions, beliefs, actions, executions), min_size=1, max_size=4)
)
def test_every_record_type_round_trips_through_mcap(tmp_path: Path, cycles: list) -> None:
    path = tmp_path / f"rt-{abs(hash(str(cycles))) % 10**9}.mcap"
    with AuditLogger(path, robot_id="rt", config=LoggerConfig(threaded=False)) as log:
        for i, (p, b, a, e) in enumerate(cycles):
            log.log_cycle(i * 1000, perception=p, belief=b, action=a, execution=e)
    read = list(open_log(path).iter_cycles())
    assert len(read) == len(cycles)
    for got, (p, b, a, e) in zip(read, cycles, strict=True):
        assert got.perception is not None and got.belief is not None
        assert got.action is not None and got.execution is not None
        assert Perception.model_validate(got.perception.model_dump(exclude={"cycle", "t_ns"})) == p
        assert Belief.model_validate(got.belief.model_dump(exclude={"cycle", "t_ns"})) == b
        assert Action.model_validate(got.action.model_dump(exclude={"cycle", "t_ns"})) == a
        assert Execution.model_validate(got.execution.model_dump(exclude={"cycle", "t_ns"})) == e
        assert got.seal is not None and got.seal.digests == got.digests()


def test_nan_is_rejected_with_a_trace_error() -> None:
    with pytest.raises(RecordError, match="deviation"):
        Execution(intended=Motion(linear=0), actual=Motion(linear=0), deviation=math.nan)


def test_wrong_types_in_a_dict_record_raise_at_the_call_site(tmp_path: Path) -> None:
    with AuditLogger(tmp_path / "x.mcap", robot_id="r", config=LoggerConfig(threaded=False)) as log:
        c = log.cycle(0)
        with pytest.raises(RecordError, match="invalid Action: rationale"):
            c.action({"command": "STOP", "rationale": "not an object"})
        c.commit()


def test_records_are_frozen_so_the_writer_sees_what_was_committed() -> None:
    motion = Motion(linear=1.0)
    with pytest.raises(Exception, match="frozen"):
        motion.linear = 2.0  # type: ignore[misc]


def test_entity_class_is_written_under_its_schema_name() -> None:
    entity = Entity(id="e", cls="person", pose=Pose(position=(0, 0, 0)), confidence={"person": 1})
    assert '"class":"person"' in entity.model_dump_json(by_alias=True)


@given(
    cycle=st.integers(0, 2**63 - 1),
    t_ns=st.integers(0, 2**63 - 1),
    digests=st.dictionaries(
        st.sampled_from(["/trace/perception", "/trace/action", "/trace/x"]),
        st.text("0123456789abcdef", min_size=64, max_size=64),
    ),
    dropped=st.integers(0, 2**31),
    sensors=st.none()
    | st.tuples(st.integers(0, 2**31), st.text("0123456789abcdef", min_size=64, max_size=64)),
)
def test_the_writers_fast_seal_encoding_equals_the_models(
    cycle: int,
    t_ns: int,
    digests: dict[str, str],
    dropped: int,
    sensors: tuple[int, str] | None,
) -> None:
    from trace_runtime.encoding.codec import encode_seal, encode_seal_fields
    from trace_runtime.records import GENESIS, Seal, SensorCover

    cover = None if sensors is None else SensorCover(count=sensors[0], digest=sensors[1])
    seal = Seal(
        cycle=cycle, t_ns=t_ns, digests=digests, prev=GENESIS, dropped=dropped, sensors=cover
    )
    fast = encode_seal_fields(cycle, t_ns, digests, GENESIS, dropped, sensors=sensors)
    assert fast == encode_seal(seal)
    assert (b'"sensors"' in fast) == (sensors is not None)  # a 1.2 seal keeps its bytes


# --- the two ways in: built records and plain dicts give the same bytes -------------------------

_LAYER_STRATEGIES = {
    Perception: perceptions,
    Belief: beliefs,
    Action: actions,
    Execution: executions,
}
_layer_records = st.one_of(*_LAYER_STRATEGIES.values())


@settings(max_examples=150, deadline=None)
@given(record=_layer_records)
def test_a_dict_gives_the_same_canonical_bytes_as_the_built_record(record: Any) -> None:
    model = type(record)
    body = model.__pydantic_serializer__.to_json(record, by_alias=True)
    want = b'{"cycle":7,"t_ns":123,' + body[1:]  # pydantic's own bytes, as v1 wrote them
    assert encode_layer(7, 123, record) == want  # orjson reading the fields
    assert layer_message(model, 7, 123, record) == want
    assert layer_message(model, 7, 123, record.model_dump(by_alias=True)) == want  # mirror
    assert layer_message(model, 7, 123, record.model_dump()) == want  # "cls": pydantic decides
    assert layer_message(model, 7, 123, orjson.loads(orjson.dumps(record.model_dump()))) == want


_bad_values = st.sampled_from(
    [math.nan, math.inf, -math.inf, None, "x", "1.5", True, -1, -1.0, 2, 2**70, [], {}, [1.0]]
)


def _paths(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every place in a JSON-like value (dict keys and list positions)."""
    found = [path]
    if isinstance(value, dict):
        for k, v in value.items():
            found += _paths(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found += _paths(v, (*path, i))
    return found


def _replace(value: Any, path: tuple[Any, ...], new: Any) -> Any:
    if not path:
        return new
    copy = dict(value) if isinstance(value, dict) else list(value)
    copy[path[0]] = _replace(value[path[0]], path[1:], new)
    return copy


@settings(max_examples=400, deadline=None)
@given(record=_layer_records, data=st.data())
def test_a_spoiled_dict_is_refused_exactly_when_pydantic_refuses_it(
    record: Any, data: st.DataObject
) -> None:
    """The msgspec mirror may only be faster than pydantic: same verdict, same bytes."""
    model = type(record)
    plain = record.model_dump(by_alias=True)
    path = data.draw(st.sampled_from(_paths(plain)[1:] or [("extra",)]))
    spoiled = _replace(plain, path, data.draw(_bad_values))
    if data.draw(st.booleans()) and isinstance(spoiled, dict):
        spoiled = {**spoiled, data.draw(st.sampled_from(["extra", "cycle"])): 1}
    try:
        expected: bytes | None = encode_layer(1, 2, model.model_validate(spoiled))
    except ValidationError:
        expected = None
    if expected is None:
        with pytest.raises(RecordError):
            check_layer(model, 1, 2, spoiled)
    else:
        assert layer_message(model, 1, 2, spoiled) == expected


def test_a_message_model_handed_over_as_its_layer_is_written_without_duplicate_keys() -> None:
    message = PerceptionMessage(cycle=3, t_ns=4, sensors_used=["lidar"])
    data = layer_message(Perception, 1, 2, message)
    assert (
        data
        == b'{"cycle":1,"t_ns":2,"entities":[],"sensors_used":["lidar"],"sensors_unavailable":[],'
        b'"robot_pose":null}'
    )


def test_a_dict_handed_over_is_copied_at_the_call_site(tmp_path: Path) -> None:
    """What was handed over is what is written, even if the robot reuses its dict."""
    capture = CaptureLogger()
    record = {"intended": {"linear": 1.0}, "actual": {"linear": 1.0}, "deviation": 0.0}
    with capture.cycle(0) as c:
        c.execution(record)
        record["deviation"] = 5.0
    assert capture.cycles[0].execution == Execution(
        intended=Motion(linear=1.0), actual=Motion(linear=1.0), deviation=0.0
    )
    assert b'"deviation":0.0' in capture.cycles[0].payloads["/trace/execution"]


@pytest.mark.parametrize("model", [Perception, Belief, Action, Execution])
def test_every_layer_model_has_a_msgspec_mirror_with_its_fields_in_order(model: Any) -> None:
    import msgspec

    mirror = _mirror(model)
    names = [f.encode_name for f in msgspec.structs.fields(mirror)]
    assert names == [f.alias or name for name, f in model.model_fields.items()]


def test_records_the_fast_encoder_does_not_know_are_written_by_pydantic() -> None:
    """A subclass of a record nested in a model, or extras put in by ``model_copy``: the
    bytes are pydantic's (declared fields only), never the object's own ``__dict__``."""

    class TaggedPose(Pose):
        tag: str = "mine"

    entity = Entity(id="e", cls="person", pose=TaggedPose(position=(1.0, 2.0, 3.0)), confidence={})
    perception = Perception(entities=[entity])
    with_extra = Motion(linear=1.0).model_copy(update={"sneaky": 1})
    execution = Execution(intended=with_extra, actual=Motion(linear=1.0), deviation=0.0)
    for record in (perception, execution):
        body = type(record).__pydantic_serializer__.to_json(record, by_alias=True)
        data = encode_layer(1, 2, record)
        assert data == b'{"cycle":1,"t_ns":2,' + body[1:]
        assert b"mine" not in data and b"sneaky" not in data


@settings(max_examples=2000)
@given(value=st.floats(allow_nan=False, allow_infinity=False) | st.text())
def test_msgspec_spells_json_as_orjson_does_below_1e16(value: float | str) -> None:
    """Why the dict path may use msgspec's encoder: the same bytes, for every float the mirror
    lets through (|x| < 1e16) and every string."""
    import msgspec

    if isinstance(value, float) and abs(value) >= 1e16:
        assert msgspec.json.encode(value) != orjson.dumps(value)  # 1e16 vs 1e+16: mirror refuses
        return
    try:
        want = orjson.dumps(value)
    except orjson.JSONEncodeError:  # lone surrogates: neither encodes them
        with pytest.raises(UnicodeEncodeError):
            msgspec.json.encode(value)
        return
    assert msgspec.json.encode(value) == want
