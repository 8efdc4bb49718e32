"""The logger's write path taken apart: the same bytes and the same errors by every way in,
and a hand-over to the writer that never loses a wake-up."""

from __future__ import annotations

import hashlib
import io
import random
import threading
import time

import pytest

from trace_runtime import EvidenceRef, Execution, Motion, Perception, RecordError
from trace_runtime.codec import encode_layer
from trace_runtime.logger import _Handover, _PendingCycle, _Wakeup
from trace_runtime.segment_writer import OutMessage, SegmentWriter
from trace_runtime.session import SessionInfo
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


def _segment_bytes(messages: list[OutMessage] | list[tuple[int, int, int, bytes]]) -> bytes:
    stream = io.BytesIO()
    session = SessionInfo(robot_id="r", period_ns=100_000_000)
    writer = SegmentWriter(stream, session)
    writer.write_batch(messages)
    writer.finish()
    return stream.getvalue()


def test_write_batch_takes_plain_tuples_and_out_messages_alike() -> None:
    rows = [(1, 0, 10, b'{"a":1}'), (2, 0, 10, b'{"b":2}'), (1, 1, 20, b'{"a":3}')]
    assert _segment_bytes([OutMessage(*row) for row in rows]) == _segment_bytes(rows)


def _pending(number: int) -> _PendingCycle:
    return _PendingCycle(number, number, {}, [], 0, -1)


def test_the_writer_side_sees_every_item_in_order_however_the_threads_interleave() -> None:
    handover = _Handover(bound=64)
    seen: list[int] = []

    def consume() -> None:
        while True:
            batch = handover.take(most=random.randint(1, 8))
            if not batch:
                return
            seen.extend(p.cycle for p in batch)
            handover.done(len(batch))
            if random.random() < 0.05:
                time.sleep(0.0001)

    consumer = threading.Thread(target=consume)
    consumer.start()
    for number in range(20_000):
        handover.put(_pending(number), block=True)
        if number % 997 == 0:
            time.sleep(0.001)  # let the consumer fall asleep now and then
    assert handover.wait_idle(10.0)
    handover.close()
    consumer.join(10.0)
    assert not consumer.is_alive()
    assert seen == list(range(20_000))


@pytest.mark.parametrize("end", ["close", "abandon"])
def test_closing_wakes_a_sleeping_writer(end: str) -> None:
    handover = _Handover(bound=4)
    got: list[list[_PendingCycle]] = []
    consumer = threading.Thread(target=lambda: got.append(handover.take(most=4)))
    consumer.start()
    time.sleep(0.05)  # asleep by now
    getattr(handover, end)()
    consumer.join(5.0)
    assert not consumer.is_alive() and got == [[]]


def test_a_wakeup_left_pending_only_makes_the_next_sleep_return_early() -> None:
    wakeup = _Wakeup()
    wakeup.wake()
    wakeup.wake()  # a second pending wake-up is the same one
    wakeup.sleep(lambda: False)  # returns at once: one was pending
    done = threading.Event()

    def sleeper() -> None:
        wakeup.sleep(lambda: False)
        done.set()

    thread = threading.Thread(target=sleeper)
    thread.start()
    assert not done.wait(0.05)  # nothing pending any more: it sleeps
    wakeup.notify()
    assert done.wait(5.0)
    thread.join()
