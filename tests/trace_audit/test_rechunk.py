"""Verdicts do not depend on how a log travelled: re-chunked by any MCAP tool, re-compressed
with any compression MCAP allows, or written from PROFILE.md alone by another language's
robot with a stock MCAP writer. Same cycles, same metrics, CLEAN; tampering still caught."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import orjson
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.writer import CompressionType, Writer

from sim import FaultRates, RunConfig, run
from trace_audit.metrics import compute_metrics
from trace_audit.verify import verify_log
from trace_runtime import open_log
from trace_runtime.chain import digest
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import LogReadError
from trace_runtime.reading.reader import open_segment
from trace_runtime.records import GENESIS, TOPIC_ACTION, TOPIC_SEAL

COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
}


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    run(RunConfig(out=out, scenario="all", cycles=40, seed=42, faults=FaultRates.off()))
    return out


def rechunk(
    src: Path,
    dst: Path,
    *,
    chunk_size: int,
    compression: str,
    mutate: Callable[[RawMessage], bytes] | None = None,
) -> Path:
    """Rewrite a segment as an MCAP tool would: every message and metadata record kept in
    file order, chunk boundaries and compression chosen by the plain ``mcap`` Writer."""
    segment = open_segment(src)
    with open(dst, "wb") as f:
        writer = Writer(f, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        writer.start(profile="trace", library="mcap rechunk (tests)")
        for name, values in segment.metadata.items():
            writer.add_metadata(name, values)
        channels: dict[str, int] = {}
        for msg in segment.iter_messages():
            if msg.topic not in channels:
                schema = writer.register_schema(name=msg.topic, encoding="jsonschema", data=b"{}")
                channels[msg.topic] = writer.register_channel(
                    topic=msg.topic, message_encoding="json", schema_id=schema
                )
            data = mutate(msg) if mutate else msg.data
            writer.add_message(
                channels[msg.topic], msg.log_time_ns, data, msg.log_time_ns, sequence=msg.sequence
            )
        writer.finish()  # type: ignore[no-untyped-call]
    return dst


def _overall(path: Path) -> dict[str, object]:
    report = compute_metrics([path])
    return dataclasses.asdict(report.overall)


def _cycles(path: Path) -> list[tuple[int, int, tuple[str, ...]]]:
    return [(c.cycle, c.t_ns, tuple(sorted(c.payloads))) for c in open_log(path).iter_cycles()]


@settings(
    max_examples=10,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    chunk_size=st.sampled_from([1, 200, 1_000, 3_000, 20_000, 1 << 20]),
    compression=st.sampled_from(sorted(COMPRESSIONS)),
)
def test_any_rechunking_verifies_clean_with_the_same_cycles_and_metrics(
    sim_log: Path, tmp_path_factory: pytest.TempPathFactory, chunk_size: int, compression: str
) -> None:
    out = rechunk(
        sim_log,
        tmp_path_factory.mktemp("re") / "re.mcap",
        chunk_size=chunk_size,
        compression=compression,
    )
    report = verify_log(out)
    assert report.ok, [f.message for f in report.findings]
    assert report.cycles == verify_log(sim_log).cycles
    assert _cycles(out) == _cycles(sim_log)
    assert _overall(out) == _overall(sim_log)


@pytest.mark.parametrize("compression", sorted(COMPRESSIONS))
def test_one_message_per_chunk_answers_questions_about_one_moment(
    sim_log: Path, tmp_path: Path, compression: str
) -> None:
    """A seek lands in a chunk that holds only the end of a cycle: the reader looks back."""
    out = rechunk(sim_log, tmp_path / "one.mcap", chunk_size=1, compression=compression)
    original, split = open_log(sim_log), open_log(out)
    for cycle in list(original.iter_cycles())[::7]:
        for t in (cycle.t_ns, cycle.t_ns + 1):
            a, b = original.cycle_at(t), split.cycle_at(t)
            assert (a.cycle, a.payloads) == (b.cycle, b.payloads)
    newest_first = [c.cycle for c in split.iter_cycles(reverse=True)]
    assert newest_first == [c.cycle for c in original.iter_cycles()][::-1]


@pytest.mark.parametrize("chunk_size", [1, 3_000])
def test_tampering_after_rechunking_is_still_found_and_located(
    sim_log: Path, tmp_path: Path, chunk_size: int
) -> None:
    target = [c for c in open_log(sim_log).iter_cycles()][17]

    def flip(msg: RawMessage) -> bytes:
        if msg.topic == TOPIC_ACTION and msg.sequence == target.cycle:
            return msg.data.replace(b'"command":"', b'"command":"X', 1)
        return msg.data

    out = rechunk(
        sim_log, tmp_path / "t.mcap", chunk_size=chunk_size, compression="zstd", mutate=flip
    )
    report = verify_log(out)
    assert not report.ok
    assert [f for f in report.findings if f.covers(target.cycle)]
    assert all(f.covers(target.cycle) for f in report.findings)


def _profile_only_log(path: Path, *, chunk_size: int, cycles: int = 30) -> Path:
    """A robot written from schemas/PROFILE.md alone (another language's situation): the
    stock MCAP writer, its own key order, size-based chunking, no checkpoints."""
    period = 100_000_000
    with open(path, "wb") as f:
        writer = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        writer.start(profile="trace", library="profile-only robot")
        writer.add_metadata(
            "trace.session",
            {
                "robot_id": "cpp-7",
                "period_ns": str(period),
                "clock": "monotonic",
                "segment": "0",
                "prev_seal": GENESIS,
                "first_cycle": "0",
                "tier": "hot",
                "profile_version": "1",
            },
        )
        channels = {
            topic: writer.register_channel(
                topic=topic,
                message_encoding="json",
                schema_id=writer.register_schema(name=name, encoding="jsonschema", data=b"{}"),
            )
            for topic, name in [
                ("/trace/action", "trace.Action"),
                ("/trace/seal", "trace.Seal"),
            ]
        }
        prev = GENESIS
        for n in range(cycles):
            t = 1_000_000_000 + n * period
            command = "STOP" if 10 <= n < 20 else "CONTINUE"
            action = orjson.dumps(
                {
                    "t_ns": t,
                    "cycle": n,
                    "command": command,
                    "alternatives": [{"command": "SLOW", "score": 0.2, "reason": "lower"}],
                    "rationale": {"summary": f"{command} by rule", "factors": []},
                }
            )
            seal = orjson.dumps(
                {
                    "cycle": n,
                    "t_ns": t,
                    "digests": {"/trace/action": digest(action)},
                    "prev": prev,
                    "dropped": 0,
                }
            )
            prev = digest(seal)
            writer.add_message(channels["/trace/action"], t, action, t, sequence=n)
            writer.add_message(channels[TOPIC_SEAL], t, seal, t, sequence=n)
        writer.finish()  # type: ignore[no-untyped-call]
    return path


@pytest.mark.parametrize("chunk_size", [1, 250, 700, 1 << 20])
def test_a_log_written_from_the_profile_alone_verifies_however_it_is_chunked(
    tmp_path: Path, chunk_size: int
) -> None:
    path = _profile_only_log(tmp_path / "cpp.mcap", chunk_size=chunk_size)
    report = verify_log(path)
    assert report.ok, [f.message for f in report.findings]
    assert report.cycles == 30
    assert [c.cycle for c in open_log(path).iter_cycles()] == list(range(30))


def test_two_robots_merged_into_one_file_are_refused_in_one_line(tmp_path: Path) -> None:
    """A file holding two sessions is not read as one robot (nor called tampering)."""
    a = _profile_only_log(tmp_path / "a.mcap", chunk_size=1 << 20)
    b_path = tmp_path / "b.mcap"
    with open(b_path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="trace", library="merge")
        session = dict(open_segment(a).metadata["trace.session"])
        writer.add_metadata("trace.session", session)
        writer.add_metadata("trace.session", {**session, "robot_id": "cpp-8"})
        channels: dict[str, int] = {}
        for msg in open_segment(a).iter_messages():
            if msg.topic not in channels:
                schema = writer.register_schema(name=msg.topic, encoding="jsonschema", data=b"{}")
                channels[msg.topic] = writer.register_channel(
                    topic=msg.topic, message_encoding="json", schema_id=schema
                )
            writer.add_message(
                channels[msg.topic], msg.log_time_ns, msg.data, msg.log_time_ns, msg.sequence
            )
        writer.finish()  # type: ignore[no-untyped-call]
    with pytest.raises(
        LogReadError, match=r"2 different trace.session records \(robots cpp-7, cpp-8\)"
    ):
        open_log(b_path)


def test_an_unknown_trace_channel_the_seal_does_not_name_is_ignored(tmp_path: Path) -> None:
    """PROFILE section 10: readers ignore channels they do not know, /trace/ ones included;
    an added layer the reader knows is still caught."""
    src = _profile_only_log(tmp_path / "src.mcap", chunk_size=1 << 20, cycles=10)

    def add(topic: str) -> Path:
        out = tmp_path / f"{topic.strip('/').replace('/', '_')}.mcap"
        segment = open_segment(src)
        with open(out, "wb") as f:
            writer = Writer(f)
            writer.start(profile="trace", library="vendor")
            writer.add_metadata("trace.session", segment.metadata["trace.session"])
            channels: dict[str, int] = {}
            for msg in segment.iter_messages():
                for name in ([topic] if msg.topic == TOPIC_SEAL else []) + [msg.topic]:
                    if name not in channels:
                        schema = writer.register_schema(
                            name=name, encoding="jsonschema", data=b"{}"
                        )
                        channels[name] = writer.register_channel(
                            topic=name, message_encoding="json", schema_id=schema
                        )
                    data = msg.data if name == msg.topic else b'{"vendor":1}'
                    writer.add_message(
                        channels[name], msg.log_time_ns, data, msg.log_time_ns, msg.sequence
                    )
            writer.finish()  # type: ignore[no-untyped-call]
        return out

    assert verify_log(add("/trace/vendor_extension")).ok
    report = verify_log(add("/trace/belief"))
    assert not report.ok
    assert all("not named by the seal" in f.message for f in report.findings)
