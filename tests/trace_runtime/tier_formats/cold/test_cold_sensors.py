"""A profile 1.3 seal's ``sensors`` digest costs the cold tier next to nothing: the codec stores
it as derived from the block's own readings when it is, as a literal when it is not (so a
tampered seal still round-trips byte for byte), and a damaged sensors column is refused.

The logs are built from the outside, message by message, as a 1.3 writer lays them out:
readings (and a ``/tf`` message the profile does not define), the layer messages, then the
seal naming their digests, the previous seal and the cover of the cycle's readings
(``trace_runtime.chain.sensor_cover``).
"""

from __future__ import annotations

import hashlib
import random
import struct

import orjson
import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trace_runtime.chain import GENESIS, digest, sensor_cover, sensor_line
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError
from trace_runtime.records import TOPIC_CHECKPOINT, TOPIC_SEAL
from trace_runtime.tier_formats.cold import (
    BlockCache,
    BlockEncoder,
    PartialBlock,
    decode_block,
    iter_blocks,
    merge_plain,
    split_plain,
)
from trace_runtime.tier_formats.cold.format import MAGIC, SENSORS

BLOCK_CYCLES = 128
_READINGS = ("/sensors/lidar", "/sensors/camera", "/sensors/ultrasonic")


def _log(
    cycles: int, *, sensors: bool = True, wrong: frozenset[int] = frozenset()
) -> list[RawMessage]:
    """A 1.3 hot message stream (``sensors``: seals carry the field; ``wrong``: cycles whose
    seal names a sensors digest that is not its readings' cover), the same for every call."""
    rng = random.Random(13)
    messages: list[RawMessage] = []
    prev = GENESIS
    for cycle in range(cycles):
        t_ns = cycle * 100_000_000
        lines: list[bytes] = []
        for topic in _READINGS[: 1 + cycle % 3]:
            data = orjson.dumps(
                {"frame": cycle, "ranges": [round(rng.uniform(0, 9), 2) for _ in range(6)]}
            )
            at = t_ns - 5_000_000
            messages.append(RawMessage(topic, cycle, at, data))
            lines.append(sensor_line(topic, cycle, at, digest(data)))
        if cycle % 4 == 1:  # a channel the profile does not define: no reading, seals ignore it
            messages.append(RawMessage("/tf", cycle, t_ns - 1_000_000, b'{"x":%d}' % cycle))
        if cycle % 50 == 7:  # a checkpoint: stored beside the block, not one of the readings
            messages.append(RawMessage(TOPIC_CHECKPOINT, cycle, t_ns, b'{"cycle":%d}' % cycle))
        digests = {}
        for topic in ("/trace/perception", "/trace/action"):
            value = {"cycle": cycle, "t_ns": t_ns, "v": round(rng.random(), 3)}
            data = orjson.dumps(value)
            messages.append(RawMessage(topic, cycle, t_ns, data))
            digests[topic] = digest(data)
        seal: dict[str, object] = {
            "cycle": cycle,
            "t_ns": t_ns,
            "digests": digests,
            "prev": prev,
            "dropped": 0,
        }
        if sensors:
            count, cover = sensor_cover(lines)
            if cycle in wrong:
                cover = hashlib.sha256(b"not the readings %d" % cycle).hexdigest()
            seal["sensors"] = {"count": count, "digest": cover}
        data = orjson.dumps(seal)
        messages.append(RawMessage(TOPIC_SEAL, cycle, t_ns, data))
        prev = digest(data)
    return messages


def _encoded(messages: list[RawMessage]) -> list[tuple[bytes, list[RawMessage]]]:
    """Each block of ``messages`` as compaction encodes it, and the block it came from."""
    encoder = BlockEncoder()
    out = []
    for block in iter_blocks(messages, BLOCK_CYCLES):
        kept, _plain, positions = split_plain(block)
        out.append((encoder.encode(kept, "hot", positions), block))
    return out


def _round_trips(data: bytes, block: list[RawMessage]) -> bool:
    _kept, plain, _positions = split_plain(block)
    decoded = decode_block(data)
    return list(merge_plain(decoded.messages, plain, decoded.plain)) == block


def _header(data: bytes) -> dict[str, object]:
    body = BlockCache(0).body(data)
    (size,) = struct.unpack_from("<I", body, 0)
    header: dict[str, object] = orjson.loads(body[4 : 4 + size])
    return header


def _sensors_columns(data: bytes) -> list[list[object]]:
    cols = _header(data)["cols"]
    assert isinstance(cols, list)
    return [col for col in cols if col[1] == ["sensors", "digest"]]


def test_derived_sensors_digests_round_trip_for_about_a_byte_a_cycle() -> None:
    cycles = 4 * BLOCK_CYCLES
    with_field = _encoded(_log(cycles))
    without = _encoded(_log(cycles, sensors=False))
    for data, block in with_field:
        assert _round_trips(data, block)
        (column,) = _sensors_columns(data)
        assert column[2] == SENSORS and column[4] == [[]]  # every one derived: no literal
    added = sum(len(d) for d, _ in with_field) - sum(len(d) for d, _ in without)
    assert added / cycles <= 1.0, f"the sensors field costs {added / cycles:.2f} B a cycle"


def test_a_seal_naming_the_wrong_sensors_digest_is_kept_as_a_literal() -> None:
    wrong = frozenset({3, BLOCK_CYCLES + 40, BLOCK_CYCLES + 41})
    for number, (data, block) in enumerate(_encoded(_log(2 * BLOCK_CYCLES, wrong=wrong))):
        assert _round_trips(data, block)
        (column,) = _sensors_columns(data)
        literals = column[4][0]  # type: ignore[index]
        stored = {
            orjson.loads(m.data)["sensors"]["digest"]
            for m in block
            if m.topic == TOPIC_SEAL and m.sequence in wrong
        }
        assert set(literals) == stored and len(literals) == (1, 2)[number]


def test_a_block_with_no_derivable_digest_codes_them_as_strings() -> None:
    everything = frozenset(range(BLOCK_CYCLES))
    ((data, block),) = _encoded(_log(BLOCK_CYCLES, wrong=everything))
    assert _round_trips(data, block)
    (column,) = _sensors_columns(data)
    assert column[2] != SENSORS


def test_a_seek_builds_a_cycle_with_its_derived_sensors_digest() -> None:
    wrong = frozenset({70})
    ((data, block),) = _encoded(_log(BLOCK_CYCLES, wrong=wrong))
    kept, _plain, _positions = split_plain(block)
    seals = [i for i, m in enumerate(kept) if m.topic == TOPIC_SEAL]
    for k in (0, 1, 63, 64, 70, 71, BLOCK_CYCLES - 1):
        cache = BlockCache(0)
        partial = PartialBlock(cache.body(data), cache.shapes)
        first = seals[k - 1] + 1 if k else 0
        assert partial.messages(first, seals[k]) == kept[first : seals[k] + 1]


def _rewritten(data: bytes, edit_column: object) -> bytes:
    """``data`` with its sensors column's header entry and body changed by ``edit_column``
    (which takes the entry and its body, and returns the new body)."""
    body = BlockCache(0).body(data)
    (size,) = struct.unpack_from("<I", body, 0)
    header = orjson.loads(body[4 : 4 + size])
    at = 4 + size + sum(header["msg"][2:])
    parts: list[bytes] = []
    for col in header["cols"]:
        part = body[at : at + col[3]]
        at += col[3]
        if col[1] == ["sensors", "digest"]:
            part = edit_column(col, part)  # type: ignore[operator]
            col[3] = len(part)
        parts.append(part)
    head = orjson.dumps(header)
    new_body = (
        struct.pack("<I", len(head)) + head + body[4 + size : 4 + size + sum(header["msg"][2:])]
    )
    return MAGIC + zstandard.ZstdCompressor().compress(new_body + b"".join(parts))


def _flag_two(col: list[object], part: bytes) -> bytes:
    return b"\x02" + part[1:]


def _one_literal_too_many(col: list[object], part: bytes) -> bytes:
    col[4] = [["0" * 64]]
    return part


def _flags_cut_short(col: list[object], part: bytes) -> bytes:
    return part[:-1]


@pytest.mark.parametrize("damage", [_flag_two, _one_literal_too_many, _flags_cut_short])
def test_a_damaged_sensors_column_is_a_format_error(damage: object) -> None:
    ((data, block),) = _encoded(_log(BLOCK_CYCLES))
    unchanged = _rewritten(data, lambda col, part: part)
    assert decode_block(unchanged).messages == split_plain(block)[0]  # the rewriting is sound
    hostile = _rewritten(data, damage)
    with pytest.raises(ColdFormatError):
        decode_block(hostile)
    cache = BlockCache(0)
    with pytest.raises(ColdFormatError):
        partial = PartialBlock(cache.body(hostile), cache.shapes)
        partial.messages(0, partial.n - 1)


@st.composite
def _cycles(draw: st.DrawFn) -> list[RawMessage]:
    """Cycles of readings and a seal whose sensors digest is its readings' cover, another
    digest, null or absent; some seals not canonical JSON (stored verbatim)."""
    messages: list[RawMessage] = []
    for cycle in range(draw(st.integers(min_value=0, max_value=12))):
        lines = []
        for _ in range(draw(st.integers(min_value=0, max_value=3))):
            topics = [*_READINGS, "/trace/perception", TOPIC_CHECKPOINT, "/tf"]
            topic = draw(st.sampled_from(topics))
            data = draw(st.sampled_from([b'{"r":1}', b'{"r":2.5}', b"\x00raw", b"[1,2]"]))
            at = draw(st.integers(min_value=0, max_value=2**40))
            messages.append(RawMessage(topic, cycle, at, data))
            if topic.startswith("/sensors/"):
                lines.append(sensor_line(topic, cycle, at, digest(data)))
        kind = draw(st.sampled_from(["cover", "cover", "other", "null", "absent", "pretty"]))
        cover = sensor_cover(lines)[1] if kind != "other" else digest(b"%d" % cycle)
        seal: dict[str, object] = {"cycle": cycle, "prev": GENESIS}
        if kind != "absent":
            seal["sensors"] = {"count": len(lines), "digest": None if kind == "null" else cover}
        data = orjson.dumps(seal) if kind != "pretty" else orjson.dumps(seal, option=2)
        messages.append(RawMessage(TOPIC_SEAL, cycle, cycle, data))
    return messages


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stream=_cycles(), block_cycles=st.integers(min_value=1, max_value=5))
def test_any_mix_of_sensors_digests_round_trips(
    stream: list[RawMessage], block_cycles: int
) -> None:
    encoder = BlockEncoder(level=1)
    for block in iter_blocks(stream, block_cycles):
        kept, _plain, positions = split_plain(block)
        data = encoder.encode(kept, "hot", positions)
        assert _round_trips(data, block)
        if kept:
            cache = BlockCache(0)
            partial = PartialBlock(cache.body(data), cache.shapes)
            assert partial.messages(0, len(kept) - 1) == kept
