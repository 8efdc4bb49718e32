"""The logger's write path taken apart: the same bytes and the same errors by every way in."""

from __future__ import annotations

import hashlib

import pytest

from trace_runtime import EvidenceRef, Execution, Motion, Perception, RecordError
from trace_runtime.encoding.codec import encode_layer
from trace_runtime.testing import CaptureLogger, synthetic_cycle


def _pydantic_bytes(cycle: int, t_ns: int, record: object) -> bytes:
    body = type(record).__pydantic_serializer__.to_json(record, by_alias=True)  # type: ignore[attr-defined]
    return b'{"cycle":%d,"t_ns":%d,' % (cycle, t_ns) + body[1:]


def test_a_layer_record_with_extras_from_model_copy_is_written_by_pydantic() -> None:
    """The stamp-and-fields fast path only takes a record whose fields are all declared."""
    record = Execution(intended=Motion(linear=1.0), deviation=0.0).model_copy(update={"sneaky": 1})
    data = encode_layer(3, 4, record)
    assert data == _pydantic_bytes(3, 4, record)
    assert b"sneaky" not in data


@pytest.mark.parametrize("index", range(0, 40, 7))
def test_synthetic_cycles_encode_to_pydantic_bytes(index: int) -> None:
    for record in synthetic_cycle(index):
        assert encode_layer(index, index * 10, record) == _pydantic_bytes(index, index * 10, record)


def test_an_empty_layer_record_gets_the_stamp_only_once() -> None:
    data = encode_layer(0, 0, Perception())
    assert data == _pydantic_bytes(0, 0, Perception())
    assert data.count(b'"cycle"') == 1


def test_sensor_returns_the_ref_evidence_ref_would_build() -> None:
    capture = CaptureLogger()
    with capture.cycle(5) as c:
        ref = c.sensor("/sensors/lidar", {"ranges": [1.0]})
    data = capture.cycles[0].sensors[0].data
    want = EvidenceRef(
        topic="/sensors/lidar", log_time_ns=5, sequence=0, digest=ref.digest or "missing"
    )
    assert ref == want and type(ref) is EvidenceRef
    assert ref.model_fields_set == want.model_fields_set
    assert ref.digest == hashlib.sha256(data).hexdigest()


def test_a_sensor_reading_at_a_negative_time_is_refused_as_before() -> None:
    capture = CaptureLogger()
    with capture.cycle(5) as c:
        with pytest.raises(RecordError) as got:
            c.sensor("/sensors/lidar", {"ranges": [1.0]}, t_ns=-1)
        with pytest.raises(RecordError) as want:
            EvidenceRef(topic="/sensors/lidar", log_time_ns=-1, sequence=1, digest="d")
    assert str(got.value) == str(want.value)
