"""Files an attacker prepared, read by the library: every read is bounded and a limit hit is
one ``LogLimitError``; malformed content is a ``LogReadError``, never another exception.

The files are built from the outside with the plain ``mcap`` library (``hostile.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.trace_runtime import hostile
from tests.trace_runtime.conftest import write_log
from trace_runtime.errors import LogLimitError, LogReadError, PayloadError
from trace_runtime.read_limits import ReadLimits
from trace_runtime.reading.logset import open_log
from trace_runtime.reading.reader import Segment
from trace_runtime.session import MIN_PERIOD_NS, SessionInfo

GIB = hostile.GIB


def _read_all(path: Path) -> int:
    """Open and read every cycle and its layers, as ``metrics`` would."""
    log = open_log(path)
    count = 0
    for cycle in log.iter_cycles():
        for topic in cycle.payloads:
            cycle.layer(topic)
        count += 1
    return count


BOMBS: dict[str, Callable[[Path, bool], Path]] = {
    "zstd 1 GiB declared": lambda p, s: hostile.zstd_bomb(p, summary=s),
    "zstd 1 GiB declared 4 KB": lambda p, s: hostile.zstd_bomb(p, declared=4096, summary=s),
    "zstd 2**62 declared": lambda p, s: hostile.huge_declared(p, summary=s),
    "lz4 1 GiB declared": lambda p, s: hostile.lz4_bomb(p, summary=s),
    "lz4 1 GiB declared 4 KB": lambda p, s: hostile.lz4_bomb(p, declared=4096, summary=s),
    "16M messages, one chunk": lambda p, s: hostile.flood(p, summary=s),
    "16M messages, 245 chunks": lambda p, s: hostile.flood(p, chunks=245, summary=s),
    "2000 messages a chunk": lambda p, s: hostile.flood(p, total=2000 * 50, chunks=50, summary=s),
}


@pytest.mark.parametrize("summary", [True, False], ids=["finished", "crashed"])
@pytest.mark.parametrize("name", list(BOMBS))
def test_a_bomb_is_one_limit_error(name: str, summary: bool, tmp_path: Path) -> None:
    path = BOMBS[name](tmp_path / "bomb.mcap", summary)
    with pytest.raises(LogLimitError, match="chunk at offset"):
        _read_all(path)


def test_a_limit_hit_in_a_recovery_scan_is_raised_not_taken_for_damage(tmp_path: Path) -> None:
    """A crashed segment is scanned and damage ends the good part; a bomb must not pass for
    damage (the segment would then read as a clean, shorter log)."""
    good = hostile.message_records([(hostile.SEAL_CHANNEL, 0, 0, b"{}")])
    bomb = hostile.RawChunk("zstd", hostile.zstd_zeros(GIB), GIB)
    path = hostile.write_segment(
        tmp_path / "crashed.mcap", [hostile.zstd_chunk(good), bomb], summary=False
    )
    with pytest.raises(LogLimitError, match="over the limit"):
        Segment(path)


def test_damage_in_a_recovery_scan_is_stepped_over_and_said(tmp_path: Path) -> None:
    good = hostile.message_records([(hostile.SEAL_CHANNEL, 0, 0, b"{}")])
    bad = hostile.zstd_chunk(good)
    bad = hostile.RawChunk("zstd", bad.data[:-3] + b"xyz", bad.declared, crc=bad.crc)
    path = hostile.write_segment(
        tmp_path / "crashed.mcap", [hostile.zstd_chunk(good), bad], summary=False
    )
    segment = Segment(path)
    # The damaged chunk stays in the table (its time range says where the damage is) but
    # reads as nothing; the good one is read.
    assert len(segment.chunks()) == 2
    (skipped,) = [offset for offset, _why in segment.skipped_chunks]
    assert segment.is_damaged(skipped)
    assert [m.topic for m in segment.iter_messages()] == ["/trace/seal"]


def test_limits_scale_with_the_compressed_size() -> None:
    limits = ReadLimits()
    assert limits.chunk_bytes(0) == limits.small_chunk_bytes
    assert limits.chunk_bytes(1 << 30) == limits.max_chunk_bytes
    assert limits.chunk_records(100) == 116
    with pytest.raises(ValueError, match="max_inflation"):
        ReadLimits(max_inflation=0)


def test_an_honest_log_is_far_inside_the_limits(tmp_path: Path) -> None:
    """The limits bite on hostile files only: a tight limit still reads an honest log."""
    path = tmp_path / "run.mcap"
    write_log(path, 50)
    tight = ReadLimits(max_inflation=64, records_per_compressed_byte=1, min_chunk_records=8)
    assert len(list(Segment(path, tight).iter_cycles())) == 50


def test_a_chunk_index_naming_a_chunk_twice_reads_it_once(tmp_path: Path) -> None:
    raw = hostile.message_records([(hostile.SEAL_CHANNEL, 0, 5, b"{}")])
    chunk = hostile.zstd_chunk(raw, start_ns=5)
    path = hostile.write_segment(tmp_path / "twice.mcap", [chunk, chunk])
    offsets = Segment(path).chunk_table()[2]
    # Point the second chunk index at the first chunk: one file offset, named twice.
    first, second = (int(o).to_bytes(8, "little") for o in offsets)
    data = path.read_bytes()
    assert data.count(second) == 1
    (tmp_path / "patched.mcap").write_bytes(data.replace(second, first))
    patched = Segment(tmp_path / "patched.mcap")
    # The index no longer agrees with the Statistics (two chunks): it is a hint, not the
    # truth, so the chunks are found in the data, each once, as the file holds them.
    assert list(patched.chunk_table()[2]) == list(offsets)
    assert len(list(patched.iter_cycles())) == 2
    assert any("Chunk Index records are not used" in note for note in patched.notes)


# --- payloads ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def honest(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("honest") / "run.mcap"
    write_log(path, 10)
    return path


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (hostile.deep_json(100_000), "depth"),
        (b"", "not JSON"),
        (b'{"cycle": 3', "not JSON"),
    ],
    ids=["nested 100,000 deep", "empty", "cut"],
)
def test_a_malformed_layer_payload_is_a_payload_error(
    payload: bytes, match: str, honest: Path, tmp_path: Path
) -> None:
    path = hostile.rewrite(
        honest,
        tmp_path / "bad.mcap",
        lambda topic, cycle, data: payload if topic == "/trace/action" and cycle == 3 else data,
    )
    cycle = next(c for c in open_log(path).iter_cycles() if c.cycle == 3)
    with pytest.raises(PayloadError, match=match) as caught:
        cycle.layer("/trace/action")
    assert isinstance(caught.value, LogReadError)
    assert "/trace/action" in str(caught.value) and "bad.mcap" in str(caught.value)
    with pytest.raises(PayloadError):
        _ = cycle.action


def test_a_payload_of_the_wrong_schema_is_a_payload_error(honest: Path, tmp_path: Path) -> None:
    path = hostile.rewrite(
        honest,
        tmp_path / "bad.mcap",
        lambda topic, cycle, data: b'{"cycle":"x"}' if topic == "/trace/seal" else data,
    )
    cycle = next(iter(open_log(path).iter_cycles()))
    with pytest.raises(PayloadError, match="not a valid Seal"):
        _ = cycle.seal


# --- trace.session -------------------------------------------------------------------------

BAD_SESSIONS = {
    "period 0": {"period_ns": "0"},
    "period 1 ns": {"period_ns": "1"},
    "period negative": {"period_ns": "-100000000"},
    "period missing": {"period_ns": ""},
    "period with underscores": {"period_ns": "100_000_000"},
    "first_cycle 1e30": {"first_cycle": "1e30"},
    "first_cycle past int64": {"first_cycle": str(1 << 63)},
    "first_cycle 10**30": {"first_cycle": str(10**30)},
    "first_cycle negative": {"first_cycle": "-1"},
    "segment negative": {"segment": "-1"},
    "segment 20 digits": {"segment": "9" * 20},
    "robot id with a slash": {"robot_id": "../etc"},
    "robot id with a space": {"robot_id": "amr 7"},
    "robot id with a newline": {"robot_id": "amr-7\nsegment=9"},
    "robot id empty": {"robot_id": ""},
    "prev_seal not a digest": {"prev_seal": "zz"},
}


@pytest.mark.parametrize("name", list(BAD_SESSIONS))
def test_an_out_of_range_session_is_refused(name: str, tmp_path: Path) -> None:
    metadata = hostile.session(**BAD_SESSIONS[name])
    with pytest.raises(ValueError, match=next(iter(BAD_SESSIONS[name]))):
        SessionInfo.from_metadata(metadata)
    raw = hostile.message_records([(hostile.SEAL_CHANNEL, 0, 0, b"{}")])
    path = hostile.write_segment(tmp_path / "s.mcap", [hostile.zstd_chunk(raw)], metadata=metadata)
    with pytest.raises(LogReadError, match=r"bad trace\.session metadata"):
        Segment(path)


def test_the_session_bounds_admit_what_the_profile_allows() -> None:
    session = SessionInfo.from_metadata(
        hostile.session(
            robot_id="A_b.c-9",
            period_ns=str(MIN_PERIOD_NS),
            first_cycle=str((1 << 63) - 1),
            segment="0",
            unknown_key="ignored",
        )
    )
    assert session.period_ns == MIN_PERIOD_NS and session.first_cycle == (1 << 63) - 1
    assert SessionInfo.from_metadata(SessionInfo("r", 100_000_000).to_metadata()).robot_id == "r"


@pytest.mark.parametrize(
    ("text", "read"),
    [("1777000000000000000", 1_777_000_000_000_000_000), ("-1", None), ("1e9", None), ("", None)],
)
def test_a_damaged_clock_step_declaration_costs_the_note_not_the_segment(
    text: str, read: int | None
) -> None:
    session = SessionInfo.from_metadata(hostile.session(clock_step_from_ns=text))
    assert session.clock_step_from_ns == read
    again = SessionInfo.from_metadata(session.to_metadata())
    assert again == session and ("clock_step_from_ns" in session.to_metadata()) == (
        read is not None
    )
