"""The reader's and the seal check's fast paths give the values of the plain ones.

``raw_message`` (the reader's constructor) and ``_seal_status`` (verify_cycle's) fill a frozen
dataclass's slots directly; ``verify_cycle(..., sensor_digest=...)`` takes digests a caller
already computed. Each must be indistinguishable from the slow path it replaces.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.trace_runtime.tlog.test_checkpoints import _write
from trace_runtime import LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.encoding.cycles import Cycle, RawMessage, raw_message
from trace_runtime.encoding.seal_check import SealStatus, _seal_status, verify_cycle

_U64 = st.integers(min_value=0, max_value=2**64 - 1)


@given(st.text(max_size=20), _U64, _U64, st.binary(max_size=64))
def test_raw_message_is_the_dataclass_value(
    topic: str, sequence: int, log_time_ns: int, data: bytes
) -> None:
    fast = raw_message(topic, sequence, log_time_ns, data)
    plain = RawMessage(topic, sequence, log_time_ns, data)
    assert type(fast) is RawMessage
    assert fast == plain and hash(fast) == hash(plain) and repr(fast) == repr(plain)
    assert replace(fast, data=b"x") == replace(plain, data=b"x")
    with pytest.raises(dataclasses.FrozenInstanceError):
        fast.data = b"changed"  # type: ignore[misc]


def _status_values() -> st.SearchStrategy[tuple[object, ...]]:
    names = st.tuples(st.text(max_size=8)).map(tuple) | st.just(())
    return st.tuples(
        st.integers(),
        st.integers(),
        st.sampled_from(["verified", "summarised", "modified", "broken_link", "unsealed"]),
        st.none() | st.text(max_size=8),
        st.none() | st.text(max_size=8),
        st.sampled_from(["ok", "broken", "unchecked"]),
        st.integers(min_value=0),
        names,
        names,
        names,
        names,
        st.integers(min_value=0),
        st.integers(min_value=0),
        names,
        st.integers(min_value=0),
        st.just(()) | st.just(({"recording": "a.mcap"},)),
        st.text(max_size=16),
    )


@given(_status_values())
def test_seal_status_fast_build_is_the_dataclass_value(values: tuple[object, ...]) -> None:
    assert len(values) == len(dataclasses.fields(SealStatus))
    fast = _seal_status(*values)
    plain = SealStatus(*values)  # type: ignore[arg-type]
    assert fast == plain and repr(fast) == repr(plain) and fast.ok == plain.ok
    assert fast.describe() == plain.describe()


@pytest.fixture()
def cycles(tmp_path: Path) -> list[Cycle]:
    """Four cycles, each citing a lidar reading by digest (written by the integrity tests'
    own helper)."""
    path = tmp_path / "run.mcap"
    _write(path, 4, LoggerConfig(threaded=False, fsync_interval_s=None))
    return list(open_log(path).iter_cycles())


def test_given_sensor_digests_check_as_hashing_them(cycles: list[Cycle]) -> None:
    """Intact, forged and unresolved readings: the same status with digests handed in."""
    asked: list[RawMessage] = []

    def known(message: RawMessage) -> str:
        asked.append(message)
        return digest(message.data)

    variants = list(cycles)
    (sensor,) = cycles[1].sensors
    forged = RawMessage(sensor.topic, sensor.sequence, sensor.log_time_ns, b'{"ranges":[9]}')
    variants.append(replace(cycles[1], sensors=[forged]))
    variants.append(replace(cycles[2], sensors=[]))
    for cycle in variants:
        assert verify_cycle(cycle, sensor_digest=known) == verify_cycle(cycle)
    assert asked, "the evidence step asked for the digests it was given"
    lying = verify_cycle(cycles[0], sensor_digest=lambda _message: "0" * 64)
    assert lying.evidence_mismatch and not lying.ok
