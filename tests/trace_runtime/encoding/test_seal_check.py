"""The per-cycle seal check (``seal_check.verify_cycle``): intact cycles, what differs, a broken
link, an unsealed cycle, a warm summary cycle."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.trace_runtime.tlog.test_checkpoints import _sync, _write
from trace_runtime import open_log
from trace_runtime.chain import digest
from trace_runtime.encoding.cycles import Cycle, RawMessage
from trace_runtime.encoding.seal_check import verify_cycle
from trace_runtime.records import GENESIS, TOPIC_ACTION, TOPIC_PERCEPTION, TOPIC_SEAL

# --- verify_cycle ---------------------------------------------------------------------------------


@pytest.fixture()
def cycles(tmp_path: Path) -> list[Cycle]:
    path = tmp_path / "run.mcap"
    _write(path, 3, _sync())
    return list(open_log(path).iter_cycles())


def test_verify_cycle_on_intact_cycles(cycles: list[Cycle]) -> None:
    prev = GENESIS
    for cycle in cycles:
        status = verify_cycle(cycle, prev)
        assert status.ok and status.state == "verified" and status.link == "ok"
        assert status.evidence_checked == 1 and status.sensors_uncited == 0
        assert status.describe() == "seal verifies"
        prev = status.seal_digest or ""
    assert verify_cycle(cycles[1]).link == "unchecked"


def test_verify_cycle_names_what_differs(cycles: list[Cycle]) -> None:
    cycle = cycles[1]
    action = cycle.payloads[TOPIC_ACTION].replace(b'"command":"', b'"command":"X')
    altered = replace(cycle, payloads={**cycle.payloads, TOPIC_ACTION: action})
    status = verify_cycle(altered)
    assert status.state == "modified" and status.modified == (TOPIC_ACTION,)
    assert "/trace/action differs from the seal's digest" in status.describe()

    missing = {t: d for t, d in cycle.payloads.items() if t != TOPIC_PERCEPTION}
    status = verify_cycle(replace(cycle, payloads=missing))
    assert status.state == "modified" and status.missing == (TOPIC_PERCEPTION,)

    (sensor,) = cycle.sensors
    forged = RawMessage(sensor.topic, sensor.sequence, sensor.log_time_ns, b'{"ranges":[9]}')
    status = verify_cycle(replace(cycle, sensors=[forged]))
    assert status.state == "modified" and not status.ok  # the 1.3 seal covers the reading
    assert "sensor readings differ from the seal's sensors digest" in status.describe()
    assert status.evidence_mismatch == ("/sensors/lidar#1",)
    before_1_3 = _without_sensor_cover(cycle)
    status = verify_cycle(replace(before_1_3, sensors=[forged]))
    assert status.state == "verified" and not status.ok  # its evidence ref alone names it
    assert status.evidence_mismatch == ("/sensors/lidar#1",)

    status = verify_cycle(cycle, digest(b"another seal"))
    assert status.state == "broken_link" and not status.ok

    bad_seal = {**cycle.payloads, TOPIC_SEAL: b'{"cycle":1'}
    assert verify_cycle(replace(cycle, payloads=bad_seal)).state == "modified"

    unsealed = {t: d for t, d in cycle.payloads.items() if t != TOPIC_SEAL}
    assert verify_cycle(replace(cycle, payloads=unsealed)).state == "unsealed"


def test_a_summary_cycle_verifies_its_seal_not_its_payloads(cycles: list[Cycle]) -> None:
    """A warm summary keeps the seal; the layer digests cannot be recomputed."""
    first, second = cycles[0], cycles[1]
    summary = replace(
        second, payloads={TOPIC_SEAL: second.payloads[TOPIC_SEAL]}, sensors=[], summary={}
    )
    status = verify_cycle(summary, digest(first.payloads[TOPIC_SEAL]))
    assert status.state == "summarised" and status.ok and status.link == "ok"
    assert set(status.summarised) == set(second.digests())
    assert status.describe() == "summarised (chain verified, payloads not retained)"
    assert verify_cycle(summary, GENESIS).state == "broken_link"


# --- the evidence step read as a shape -----------------------------------------------------


def _without_sensor_cover(cycle: Cycle) -> Cycle:
    """``cycle`` as a writer before profile 1.3 sealed it: no ``sensors`` in its seal."""
    seal = orjson.loads(cycle.payloads[TOPIC_SEAL])
    del seal["sensors"]
    return replace(cycle, payloads={**cycle.payloads, TOPIC_SEAL: orjson.dumps(seal)})


def _resealed(cycle: Cycle, perception: Any) -> Cycle:
    """``cycle`` with another perception message and a seal naming its digest; the seal is
    one of profile 1.2 (no ``sensors``), so its readings are covered by the evidence alone."""
    data = perception if isinstance(perception, bytes) else json.dumps(perception).encode()
    seal = orjson.loads(cycle.payloads[TOPIC_SEAL])
    seal["digests"][TOPIC_PERCEPTION] = digest(data)
    seal.pop("sensors", None)
    payloads = {**cycle.payloads, TOPIC_PERCEPTION: data, TOPIC_SEAL: orjson.dumps(seal)}
    return replace(cycle, payloads=payloads)


def _ref_variants(cycle: Cycle) -> list[Any]:
    """Perceptions that exercise every branch of the evidence step (and the shape's refusals)."""
    value = orjson.loads(cycle.payloads[TOPIC_PERCEPTION])
    ref = value["entities"][0]["evidence"][0]["ref"]

    def with_refs(*refs: Any) -> Any:
        entity = {**value["entities"][0], "evidence": [{"sensor": "x", "ref": r} for r in refs]}
        return {**value, "entities": [entity, {"id": "bare"}, {"id": "empty", "evidence": []}]}

    external = {**ref, "recording": "camera.mcap", "topic": "/image", "sequence": None}
    return [
        value,
        with_refs(ref, ref),
        with_refs({**ref, "sequence": None}),
        with_refs({**ref, "sequence": 99}, {**ref, "sequence": 99, "log_time_ns": 5}),
        with_refs({**ref, "digest": "0" * 64}, {**ref, "digest": None}, None, {}),
        with_refs({**ref, "topic": "/sensors/none"}),
        with_refs(ref, external),
        with_refs(external, {**external, "recording": "other.mcap"}),
        with_refs({**ref, "digest": 7}),  # a type the shape refuses: the full parse
        with_refs({**ref, "sequence": 2**70}),  # past int64: the full parse
        {**value, "entities": None},
        {**value, "entities": [1, 2]},
        [value],
        b'{"entities":[{"id":"a","evidence":[{"ref":{"topic":"\\u002fsensors/lidar"}}]}]}',
        b"not json",
    ]


def _outcome(check: Any) -> Any:
    try:
        return check()
    except Exception as err:  # the test compares what each path raises
        return type(err)


def test_the_evidence_shape_gives_the_whole_parse_status(cycles: list[Cycle]) -> None:
    """A sealed perception's refs read as the metrics' shape give exactly the status the whole
    JSON gives (``perception_json`` handed in is the old path), external refs whole."""
    cycle = cycles[1]
    (sensor,) = cycle.sensors
    forged = RawMessage(sensor.topic, sensor.sequence, sensor.log_time_ns, b'{"ranges":[9]}')
    for perception in _ref_variants(cycle):
        for sensors in (cycle.sensors, [forged], []):
            case = replace(_resealed(cycle, perception), sensors=sensors)
            data = case.payloads[TOPIC_PERCEPTION]
            try:
                whole = orjson.loads(data)
            except orjson.JSONDecodeError:
                whole = None
            got = _outcome(lambda: verify_cycle(case))  # noqa: B023 - called at once
            if whole is not None:
                assert got == _outcome(lambda: verify_cycle(case, perception_json=whole)), data  # noqa: B023
            if isinstance(got, type):
                continue  # what the whole parse raises (entities that are not objects), as before
            assert got.state == "verified", got
            if b"camera.mcap" in data:
                assert got.external and all("recording" in r for r in got.external)
