"""doctor's fast path for a message's bytes (``codec.decode_canonical``) says nothing the
slow path would not: bytes it takes are canonical and valid by ``parse_canonical`` and
``validate_parsed``, and doctor's findings on faulty, hostile and re-encoded logs are the
same with it and without it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mcap_variants import rewrite as rewrite_layout
from tests.mcap_variants import single_changes
from tests.trace_audit.conftest import rewrite_segment, write_log
from tests.trace_audit.profile_writer import Faults, write_profile_log
from tests.trace_runtime import hostile
from tests.trace_runtime.encoding.test_validate_parsed import _MESSAGE_OF, _seals
from tests.trace_runtime.test_records import _bad_values, _layer_records, _paths, _replace
from trace_audit.doctor import DoctorReport, doctor_log
from trace_audit.doctor import content as content_module
from trace_audit.doctor.content import parse_canonical
from trace_runtime.encoding.codec import decode_canonical, validate_parsed
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.records import MESSAGE_MODELS, TOPIC_SEAL


def _spelled(value: Any, how: str) -> bytes:
    """``value`` as bytes, canonical or spelled in one of the ways a writer may get wrong."""
    if how == "spaced":
        return json.dumps(value).encode()
    if how == "escaped":  # non-ASCII as \\u escapes: compact, valid, not orjson's spelling
        return json.dumps(value, separators=(",", ":"), ensure_ascii=True).encode()
    if how == "reordered" and isinstance(value, dict) and len(value) > 1:
        keys = list(value)
        return orjson.dumps({k: value[k] for k in [*keys[1:], keys[0]]})
    if how == "repeated" and isinstance(value, dict) and value:
        first = next(iter(value))
        return b'{"%s":0,' % first.encode() + orjson.dumps(value)[1:]
    if how == "bom":
        return b"\xef\xbb\xbf" + orjson.dumps(value)
    return orjson.dumps(value)


@settings(max_examples=400, deadline=None)
@given(record=_layer_records, seal=_seals, data=st.data())
def test_bytes_the_fast_path_takes_are_canonical_and_valid(
    record: Any, seal: dict[str, Any], data: st.DataObject
) -> None:
    layer = data.draw(st.booleans())
    if not layer:
        model: Any = MESSAGE_MODELS[TOPIC_SEAL]
        plain: Any = seal  # (its keys in any order)
    else:
        model = _MESSAGE_OF[type(record)]
        t_ns = data.draw(st.integers(0, 2**63 - 1))
        stamp = {"cycle": data.draw(st.integers(0, 2**40)), "t_ns": t_ns}
        plain = {**stamp, **record.model_dump(by_alias=True, mode="json")}
    plain = orjson.loads(orjson.dumps(plain))
    spoiled = plain
    if data.draw(st.booleans()):
        path = data.draw(st.sampled_from(_paths(plain)[1:]))
        spoiled = _replace(plain, path, data.draw(_bad_values))
    how = data.draw(st.sampled_from(["canonical", "spaced", "escaped", "reordered", "repeated"]))
    how = data.draw(st.sampled_from([how, "bom"]))
    try:
        raw = _spelled(spoiled, how)
    except (TypeError, ValueError, orjson.JSONEncodeError):
        return  # NaN or a 70-bit integer: orjson will not write it, neither would a writer
    fast = decode_canonical(model, raw)
    if fast is not None:
        value, why = parse_canonical(raw)
        assert why == ""
        validate_parsed(model, value)  # raises if it is not valid
        assert (fast.cycle, fast.t_ns) == (value["cycle"], value["t_ns"])
    elif layer and spoiled is plain and how == "canonical" and b"e+" not in raw:
        # (floats from 1e16 up are spelled alike by orjson and msgspec no more: slow path)
        pytest.fail("the canonical bytes of a valid layer message missed the fast path")


def test_the_fast_path_is_taken_for_the_messages_our_logger_writes(tmp_path: Path) -> None:
    """Not dead code: every layer message but the perception (whose refs need the parse
    anyway) and every 1.3 seal of a log our logger wrote goes through it."""
    from trace_runtime.reading.reader import open_segment

    path = write_log(tmp_path / "run.mcap")
    taken = {
        topic: decode_canonical(MESSAGE_MODELS[topic], data) is not None
        for cycle in open_segment(path).iter_cycles()
        for topic, data in cycle.payloads.items()
        if topic in MESSAGE_MODELS
    }
    assert taken and all(taken.values()), taken


def _report(report: DoctorReport) -> Any:
    return [dataclasses.asdict(segment) for segment in report.segments]


def _both_ways(path: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[Any, Any]:
    fast = _report(doctor_log(path))
    with monkeypatch.context() as patched:
        patched.setattr(content_module, "decode_canonical", lambda model, data: None)
        slow = _report(doctor_log(path))
    return fast, slow


def _spoil_bytes(message: RawMessage) -> bytes | None:
    """A handful of byte-level deviations doctor reports, at different cycles."""
    if message.sequence == 3 and message.topic == "/trace/belief":
        return json.dumps(orjson.loads(message.data)).encode()  # spaced
    if message.sequence == 5 and message.topic == "/trace/execution":
        return b'{"cycle":5,' + message.data[1:]  # a repeated key
    if message.sequence == 7 and message.topic == TOPIC_SEAL:
        value = orjson.loads(message.data)
        value.pop("sensors", None)
        return orjson.dumps(value)  # a 1.3 seal without sensors (and no longer its digest)
    if message.sequence == 9 and message.topic == "/trace/action":
        value = orjson.loads(message.data)
        value["score"] = "high"  # not valid
        return orjson.dumps(value)
    return message.data


_FAULTS = [
    Faults(),
    Faults(spaced_json=True, log_time_off_by=3, sequence_off_by=1),
    Faults(profile_version="1.3", seal_without_sensors_at=4, unsealed_tail=True),
    Faults(sensor_after_layers=True, clock_step_back_at=10, lz4=True),
]


@pytest.mark.parametrize("faults", _FAULTS, ids=range(len(_FAULTS)))
def test_doctor_finds_the_same_on_profile_written_logs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, faults: Faults
) -> None:
    fast, slow = _both_ways(write_profile_log(tmp_path / "p.mcap", faults=faults), monkeypatch)
    assert fast == slow


def test_doctor_finds_the_same_on_spoiled_bytes_and_every_layout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    source = write_log(tmp_path / "run.mcap")
    spoiled = rewrite_segment(source, tmp_path / "spoiled.mcap", _spoil_bytes, chunk_size=4096)
    fast, slow = _both_ways(spoiled, monkeypatch)
    assert fast == slow
    assert {p["rule"] for s in fast for p in s["problems"]} >= {"compact-json", "schema-valid"}
    for i, variant in enumerate(single_changes()):
        copy = rewrite_layout(source, tmp_path / f"v{i}.mcap", variant)
        fast, slow = _both_ways(copy, monkeypatch)
        assert fast == slow, variant


def test_doctor_finds_the_same_on_hostile_message_bytes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Layer messages an attacker wrote: nested past every parser's depth, a record with a
    deep value where the schema wants a number, junk, a lone surrogate, a huge number."""
    deep_value = b'{"cycle":1,"t_ns":1,"nodes":' + hostile.deep_json(5000) + b',"edges":[]}'
    bodies = [
        hostile.deep_json(5000),
        deep_value,
        b"\x00\xff junk",
        b'{"cycle":2,"t_ns":2,"nodes":[],"edges":[],"x":"\\ud800"}',
        b'{"cycle":3,"t_ns":3,"digests":{},"prev":"' + b"0" * 64 + b'","dropped":1e400}',
    ]
    messages = [(2 if i < 4 else hostile.SEAL_CHANNEL, i, i, b) for i, b in enumerate(bodies)]
    path = hostile.write_segment(
        tmp_path / "h.mcap", [hostile.zstd_chunk(hostile.message_records(messages))]
    )
    fast, slow = _both_ways(path, monkeypatch)
    assert fast == slow
