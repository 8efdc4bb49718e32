"""The cold codec is lossless: any message stream decodes byte for byte, seals verify, and a
seek into a cold segment decodes one block and finds the same cycle as the hot original."""

from __future__ import annotations

import hashlib
import json
import random
import shutil
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.trace_runtime.tier_logs import make_root
from trace_runtime import open_log, open_segment
from trace_runtime.chain import digest
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError
from trace_runtime.records import TOPIC_CHECKPOINT, TOPIC_SEAL
from trace_runtime.tier_formats import cold as cold_module
from trace_runtime.tier_formats.cold import (
    BlockCache,
    BlockEncoder,
    PartialBlock,
    decode_block,
    iter_blocks,
    split_plain,
)
from trace_runtime.tier_formats.cold import encode as encode_module
from trace_runtime.tier_formats.warm import WarmPolicy
from trace_runtime.tiers import ColdOptions, chain_problems, compact

# --- the codec on arbitrary input ---------------------------------------------------------------

_scalars = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.decimals(places=3, min_value=-1000, max_value=1000, allow_nan=False).map(float)
    | st.text(max_size=12)
    | st.sampled_from(["ped_1", "ped_2", "person", "lidar", "m", ""])
)
_json = st.recursive(
    _scalars,
    lambda inner: (
        st.lists(inner, max_size=5)
        | st.dictionaries(
            st.sampled_from(["id", "p", "x", "y", "value", "ref", "é", "k"]), inner, max_size=5
        )
    ),
    max_leaves=25,
)
_TOPICS = ["/trace/perception", "/trace/action", "/sensors/lidar", TOPIC_SEAL, TOPIC_CHECKPOINT]


@st.composite
def _streams(draw: st.DrawFn) -> list[RawMessage]:
    """Message streams as a block sees them: JSON (canonical or not), bytes, and digests of
    earlier messages (what seals and evidence refs carry)."""
    messages: list[RawMessage] = []
    for _ in range(draw(st.integers(min_value=0, max_value=24))):
        kind = draw(st.sampled_from(["json", "json", "json", "pretty", "bytes", "digest"]))
        value = draw(_json)
        if kind == "bytes":
            data = draw(st.binary(max_size=40))
        elif kind == "pretty":
            data = json.dumps(value, indent=1).encode()
        else:
            if kind == "digest" and messages:
                earlier = draw(st.sampled_from(messages))
                value = {"d": hashlib.sha256(earlier.data).hexdigest(), "v": value}
            try:
                data = orjson.dumps(value)
            except orjson.JSONEncodeError:  # integers beyond 64 bits: keep them as text
                data = json.dumps(value, separators=(",", ":")).encode()
        messages.append(
            RawMessage(
                draw(st.sampled_from(_TOPICS)),
                draw(st.integers(min_value=0, max_value=2**32 - 1)),  # MCAP sequence: u32
                draw(st.integers(min_value=0, max_value=2**64 - 1)),  # log time: u64
                data,
            )
        )
    return messages


def _open_partial(block: bytes) -> PartialBlock:
    """A block opened for a partial decode, as a seek opens it."""
    cache = BlockCache(0)
    return PartialBlock(cache.body(block), cache.shapes)


def _round_trip(encoder: BlockEncoder, block: list[RawMessage]) -> list[RawMessage]:
    kept, plain, positions = split_plain(block)
    decoded = decode_block(encoder.encode(kept, "hot", positions))
    assert decoded.plain == positions
    return list(cold_module.merge_plain(decoded.messages, plain, decoded.plain))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stream=_streams())
def test_any_message_stream_decodes_byte_for_byte(stream: list[RawMessage]) -> None:
    encoder = BlockEncoder(level=1)
    assert _round_trip(encoder, stream) == stream
    # and again with the encoder's shape and scale caches warm from the first block
    assert _round_trip(encoder, stream[::-1]) == stream[::-1]


@settings(max_examples=60, deadline=None)
@given(
    rows=st.lists(
        st.tuples(
            st.floats(allow_nan=False, allow_infinity=False, width=64),
            st.integers(min_value=-(2**63), max_value=2**63 - 1),
            st.one_of(st.none(), st.floats(-5, 5).map(lambda x: round(x, 2))),
            st.lists(st.floats(0, 50).map(lambda x: round(x, 3)), max_size=6),
            st.sampled_from([0.0, -0.0, 1.5, -1.5]),
        ),
        min_size=1,
        max_size=40,
    )
)
def test_columns_of_one_shape_round_trip(rows: list[tuple[Any, ...]]) -> None:
    """Many messages of one shape: the column codecs (delta, decimal, nullable, vectors)."""
    stream = [
        RawMessage("/trace/x", i, 1000 + i, orjson.dumps({"f": f, "i": n, "o": o, "v": v, "z": z}))
        for i, (f, n, o, v, z) in enumerate(rows)
    ]
    assert _round_trip(BlockEncoder(level=1), stream) == stream


def test_corrupt_blocks_raise_a_format_error() -> None:
    encoder = BlockEncoder()
    block = encoder.encode([RawMessage("/t", 0, 0, b'{"a":1}')], "hot")
    with pytest.raises(ColdFormatError):
        decode_block(b"XXXX" + block[4:])
    with pytest.raises(ColdFormatError):
        decode_block(block[:-3])


# --- cold segments ------------------------------------------------------------------------------


@pytest.fixture
def hot_and_cold(tmp_path: Path) -> tuple[Path, Path]:
    hot = make_root(tmp_path / "hot", cycles=150, segments=2)
    cold = tmp_path / "cold"
    import shutil

    shutil.copytree(hot, cold)
    report = compact(cold, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=16))
    assert [s.status for s in report.segments] == ["compacted", "compacted"]
    assert not list((cold / "hot").glob("*.mcap"))
    return hot, cold


def test_cold_segments_give_the_same_cycles(hot_and_cold: tuple[Path, Path]) -> None:
    hot, cold = (open_log(p) for p in hot_and_cold)
    assert [s.session.tier for s in cold.segments] == ["cold", "cold"]
    assert (cold.start_ns, cold.end_ns) == (hot.start_ns, hot.end_ns)
    hot_cycles = list(hot.iter_cycles())
    assert list(cold.iter_cycles()) == hot_cycles
    assert list(cold.iter_cycles(reverse=True)) == hot_cycles[::-1]
    # payloads byte for byte, sensors included
    for a, b in zip(hot_cycles, cold.iter_cycles(), strict=True):
        assert a.payloads == b.payloads and a.sensors == b.sensors
    # windows that start and end inside blocks
    rng = random.Random(7)
    for _ in range(20):
        start = rng.randrange(hot.start_ns, hot.end_ns)
        end = start + rng.randrange(0, 3_000_000_000)
        assert list(cold.iter_cycles(start, end)) == list(hot.iter_cycles(start, end))
    assert cold.get_cycle(hot_cycles[200].cycle) == hot_cycles[200]


def test_seek_into_a_cold_segment_decodes_one_block(
    hot_and_cold: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    hot, cold = (open_log(p) for p in hot_and_cold)
    calls = []
    real = BlockCache.body  # where every decode, whole or partial, starts

    def counting(self: BlockCache, block: bytes) -> Any:
        calls.append(1)
        return real(self, block)

    monkeypatch.setattr(BlockCache, "body", counting)
    rng = random.Random(3)
    for t_ns in [
        hot.start_ns,
        hot.end_ns,
        *(rng.randrange(hot.start_ns, hot.end_ns) for _ in range(30)),
    ]:
        calls.clear()
        cold.clear_caches()
        assert cold.cycle_at(t_ns) == hot.cycle_at(t_ns)
        assert len(calls) <= 2  # the block that starts at or before t (and, rarely, the one before)
    middle = hot.start_ns + (hot.end_ns - hot.start_ns) // 2
    calls.clear()
    cold.clear_caches()
    found = cold.cycle_at(middle)
    assert found.t_ns <= middle < found.t_ns + 100_000_000
    assert len(calls) == 1
    # asking again about that decision (an investigation does, often) decodes nothing new
    assert cold.cycle_at(found.t_ns) == found
    assert len(calls) == 1


def test_seals_verify_after_cold_reencoding(hot_and_cold: tuple[Path, Path]) -> None:
    _hot, cold = hot_and_cold
    segments = open_log(cold).segments
    prev = None
    for segment in segments:
        assert chain_problems(segment) == []
        if prev is not None:
            assert segment.session.prev_seal == prev
        for cycle in segment.iter_cycles():
            seal = orjson.loads(cycle.payloads[TOPIC_SEAL])
            assert seal["digests"] == cycle.digests()
            prev = digest(cycle.payloads[TOPIC_SEAL])


def test_cold_keeps_checkpoints_readable_without_decoding(hot_and_cold: tuple[Path, Path]) -> None:
    hot, cold = hot_and_cold
    for name in ("amr-1_000000.mcap", "amr-1_000001.mcap"):
        source = open_segment(hot / "hot" / name)
        target = open_segment(cold / "cold" / name)
        want = [m for m in source.iter_messages() if m.topic == TOPIC_CHECKPOINT]
        assert want  # at least the closing checkpoint
        assert [m for m in target.iter_messages() if m.topic == TOPIC_CHECKPOINT] == want
        assert list(cold_module.iter_decoded(target.iter_messages())) == list(
            source.iter_messages()
        )
        meta = target.metadata["trace.tier"]
        assert meta["lossy"] == "false" and meta["codec"] == "trace-cold-v1"
        assert meta["verbatim_messages"] == "0"


def test_cold_from_warm_keeps_the_summaries(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=120)
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_ns=500_000_000))
    warm = list(open_log(root).iter_cycles())
    assert any(c.is_summary for c in warm)
    report = compact(root, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=32))
    assert [s.source_tier for s in report.segments] == ["warm"]
    assert list(open_log(root).iter_cycles()) == warm
    segment = open_log(root).segments[0]
    assert segment.metadata["trace.tier"]["lossy"] == "true"  # lossless of a lossy source


def test_a_damaged_cold_block_is_skipped_and_said_not_a_crash(
    hot_and_cold: tuple[Path, Path],
) -> None:
    _hot, cold = hot_and_cold
    path = cold / "cold" / "amr-1_000000.mcap"
    before = len(list(open_segment(path).iter_cycles()))
    data = bytearray(path.read_bytes())
    at = data.find(b"TCB\x01") + 200
    data[at] ^= 0xFF
    path.write_bytes(bytes(data))
    segment = open_segment(path)
    after = len(list(segment.iter_cycles()))
    assert segment.skipped_chunks
    assert 0 < after < before


def test_blocks_split_on_whole_cycles() -> None:
    stream = [
        RawMessage(t, i, i, b"{}")
        for i, t in enumerate(["/s", "/trace/a", TOPIC_SEAL, "/trace/a", TOPIC_SEAL, "/trace/a"])
    ]
    blocks = list(iter_blocks(stream, 1))
    assert [[m.topic for m in b] for b in blocks] == [
        ["/s", "/trace/a", TOPIC_SEAL],
        ["/trace/a", TOPIC_SEAL],
        ["/trace/a"],
    ]


# --- partial decodes (a seek builds one cycle) --------------------------------------------------


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stream=_streams())
def test_the_encoders_check_decodes_as_a_plain_decode_does(stream: list[RawMessage]) -> None:
    """The check takes digest references from the encoder's digests of its input instead of
    hashing decoded messages again: what it returns is what any reader decodes."""
    kept, _plain, positions = split_plain(stream)
    data, checked = BlockEncoder(level=1).encode_checked(kept, "hot", positions)
    assert checked.messages == decode_block(data).messages == kept


def test_the_check_decode_uses_the_digests_it_is_given() -> None:
    """With a wrong digest for a referenced message, the check decode differs from the input
    (so ``encode_checked`` would not accept the block): it is the comparison with the input
    that makes the borrowed digests safe."""
    chain = [RawMessage("/t", 0, 0, b'{"i":0}')]
    for i in range(1, 30):
        prev = hashlib.sha256(chain[-1].data).hexdigest()
        chain.append(RawMessage("/t", i, i, orjson.dumps({"i": i, "prev": prev})))
    data, checked = BlockEncoder(level=1).encode_checked(chain, "hot")
    assert checked.messages == chain
    wrong = [hashlib.sha256(m.data).hexdigest() for m in chain]
    wrong[10] = "0" * 64
    decoded = BlockCache(0).decode_checked(data, wrong).messages
    assert decoded[:11] == chain[:11]
    assert decoded[11] != chain[11]


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stream=_streams(), data=st.data())
def test_a_partial_decode_gives_the_bytes_of_a_whole_one(
    stream: list[RawMessage], data: st.DataObject
) -> None:
    kept, _plain, positions = split_plain(stream)
    kept = kept or [RawMessage("/t", 0, 0, b'{"a":1}')]
    block = BlockEncoder(level=1).encode(kept, "hot", positions)
    whole = decode_block(block).messages
    first = data.draw(st.integers(0, len(kept) - 1))
    last = data.draw(st.integers(first, len(kept) - 1))
    partial = _open_partial(block)
    assert partial.messages(first, last) == whole[first : last + 1]
    assert partial.messages(0, len(kept) - 1) == whole  # and the rest, after a first part


def test_a_partial_decode_reads_columns_that_vectors_and_scalars_share() -> None:
    """``[1, 2, 3]`` is a vector (element columns p.0, p.1, p.2); ``[{..}, 2, 3]`` has scalar
    leaves p.1 and p.2 in the same columns; ``null`` is a scalar leaf on the vector's path."""
    values = [
        {"p": [{"x": 1}, 5, 6]},
        {"p": None},
        {"p": [1, 2, 3]},
        {"p": [{"x": 2}, 7, 8]},
        {"p": [4, 5, 6]},
        {"p": None},
    ]
    stream = [RawMessage("/t", i, i, orjson.dumps(v)) for i, v in enumerate(values * 3)]
    encoder = BlockEncoder(level=1)
    block = encoder.encode(stream, "hot")
    assert encoder.raw_messages == 0  # coded as columns, not kept verbatim
    whole = decode_block(block).messages
    assert whole == stream
    for first in range(len(stream)):
        for last in range(first, len(stream)):
            partial = _open_partial(block)
            assert partial.messages(first, last) == stream[first : last + 1]


def test_seal_anchors_bound_what_a_seek_builds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    hot = make_root(tmp_path / "hot", cycles=150)
    cold = tmp_path / "cold"
    shutil.copytree(hot, cold)
    monkeypatch.setattr(encode_module, "SEAL_ANCHOR_CYCLES", 8)
    compact(cold, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=64))
    hot_log, cold_log = open_log(hot), open_log(cold)
    segment = cold_log.segments[0]
    blocks = [m.data for m in segment.iter_messages() if m.topic == cold_module.BLOCK_TOPIC]
    assert len(blocks) == 3
    for data in blocks:
        partial = _open_partial(data)
        whole = decode_block(data).messages
        seals = [i for i, m in enumerate(whole) if m.topic == TOPIC_SEAL]
        last_span = (seals[-2] + 1, seals[-1])
        assert partial.messages(*last_span) == whole[last_span[0] : last_span[1] + 1]
        built = [i for i, d in enumerate(partial.datas) if d is not None]
        # the last cycle's chain starts at the anchor 8 seals back at most, not at seal 0
        anchor = seals[(len(seals) - 1) // 8 * 8 - 1] if len(seals) > 8 else -1
        assert min(i for i in built if whole[i].topic == TOPIC_SEAL) > anchor
    # every cycle found by a seek, byte for byte as in the hot original
    for cycle in hot_log.iter_cycles():
        cold_log.segments[0].clear_caches()
        assert cold_log.cycle_at(cycle.t_ns) == cycle
    assert chain_problems(segment) == []


def test_a_seek_into_a_block_that_ends_unsealed_matches_assembling_it() -> None:
    stream = [
        RawMessage(topic, i // 3, 100 * i, orjson.dumps({"cycle": i // 3, "v": i}))
        for i, topic in enumerate(["/trace/action", "/sensors/x", TOPIC_SEAL] * 3)
    ]
    stream.append(RawMessage("/trace/action", 3, 5_000, b'{"cycle":3,"v":9}'))  # never sealed
    block = BlockEncoder(level=1).encode(stream, "hot")
    run = [RawMessage(cold_module.BLOCK_TOPIC, 0, 0, block)]
    whole = cold_module.assemble_cold(run, "seg")
    assert [c.sealed for c in whole] == [True, True, True, False]
    for t_ns in (-1, 0, 200, 250, 500, 800, 4_999, 5_000, 9_000):
        expected = [c for c in whole if c.t_ns <= t_ns]
        found = cold_module.ColdAssembler().cycle_at(run, "seg", t_ns)
        assert found == (expected[-1] if expected else None)
    # a block that ends with its seal takes the partial path: the same answers
    sealed = BlockEncoder(level=1).encode(stream[:-1], "hot")
    run = [RawMessage(cold_module.BLOCK_TOPIC, 0, 0, sealed)]
    assembler = cold_module.ColdAssembler()
    for t_ns in (0, 200, 499, 500, 800, 9_000):
        expected = [c for c in whole[:3] if c.t_ns <= t_ns]
        assert assembler.cycle_at(run, "seg", t_ns) == (expected[-1] if expected else None)
