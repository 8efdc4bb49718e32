"""``trace-audit doctor``: our logs and a log written from PROFILE.md alone conform; each
deviation from the profile is named by its rule, PROFILE section and level, located, and
gives the documented exit code."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import rewrite_segment, write_log
from tests.trace_audit.profile_writer import Faults, write_profile_log
from trace_audit.cli import app
from trace_audit.doctor import RULES, DoctorReport, doctor_log
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import LogReadError

V1_FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "v1" / "amr-fixture_000000.mcap"


def _broken(report: DoctorReport) -> set[str]:
    return {p.rule for p in report.errors}


def test_a_log_written_from_the_profile_alone_with_the_plain_mcap_writer_conforms(
    tmp_path: Path,
) -> None:
    report = doctor_log(write_profile_log(tmp_path / "p.mcap"))
    assert report.conforms, report.errors
    segment = report.segments[0]
    assert (segment.cycles, segment.messages, segment.closed) == (30, 181, True)
    # The stock writer cuts chunks by size: allowed, and noted as the writer SHOULD it
    assert {p.rule for p in report.notes} == {"cycle-in-chunk"}


@pytest.mark.parametrize("finish", [True, False], ids=["finished", "crashed"])
def test_logs_written_by_our_logger_conform(tmp_path: Path, finish: bool) -> None:
    report = doctor_log(write_log(tmp_path / "run.mcap", finish=finish))
    assert report.conforms, report.errors
    assert report.segments[0].cycles > 0
    if not finish:
        assert "closed" in {p.rule for p in report.notes}


def test_the_committed_v1_fixture_still_conforms(tmp_path: Path) -> None:
    copy = shutil.copy(V1_FIXTURE, tmp_path / V1_FIXTURE.name)
    assert doctor_log(copy).conforms


def test_a_log_root_with_several_segments_conforms(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root", max_segment_s=3.0)
    report = doctor_log(root)
    assert len(report.segments) >= 3
    assert report.conforms, report.errors


@pytest.mark.parametrize("tier", ["warm", "cold"])
def test_compacted_tiers_conform(tmp_path: Path, tier: str) -> None:
    """Warm and cold segments carry their own channels (and cold its own encoding): they are
    the profile's section 9, not deviations from section 3."""
    root = write_log(tmp_path / "root", max_segment_s=3.0)
    moved = CliRunner().invoke(
        app, ["compact", str(root), "--tier", tier, "--older-than", "1s", "--plain"]
    )
    assert moved.exit_code == 0, moved.output
    assert list((root / tier).glob("*.mcap"))
    report = doctor_log(root)
    assert report.conforms, report.errors
    assert not [p for p in report.notes if p.rule in ("known-channel", "chunk-compression")]


def test_log_time_differing_from_t_ns_names_the_rule_section_and_place(tmp_path: Path) -> None:
    report = doctor_log(write_profile_log(tmp_path / "p.mcap", faults=Faults(log_time_off_by=7)))
    assert not report.conforms
    [problem] = report.errors
    assert (problem.rule, problem.section, problem.level) == ("log-time", "§4", "MUST")
    assert "/trace/action" in problem.message and "1000000007" in problem.message
    assert problem.cycle == 0 and problem.offset is not None and problem.offset > 0
    assert problem.count == 30  # every cycle, reported once


@pytest.mark.parametrize(
    ("faults", "rule", "section"),
    [
        (Faults(sequence_off_by=1), "sequence", "§4"),
        (Faults(sensor_after_layers=True), "cycle-layout", "§5"),
        (Faults(spaced_json=True), "compact-json", "§6"),
        (Faults(profile="ros2"), "header-profile", "§1"),
        (Faults(second_session=True), "session", "§2"),
        (Faults(no_session=True), "session", "§2"),
        (Faults(schema_encoding="json"), "channel-schema", "§3"),
        (Faults(unsealed_tail=True), "sealed", "§5"),
    ],
    ids=lambda v: v if isinstance(v, str) and not v.startswith("§") else "",
)
def test_each_deviation_breaks_exactly_its_rule(
    tmp_path: Path, faults: Faults, rule: str, section: str
) -> None:
    report = doctor_log(write_profile_log(tmp_path / "p.mcap", faults=faults))
    assert _broken(report) == {rule}
    assert {p.section for p in report.errors} == {section}
    assert RULES[rule].level == "MUST"


def test_a_1_3_log_from_the_profile_alone_seals_every_reading(tmp_path: Path) -> None:
    """A writer that follows PROFILE §6's ``sensors`` text, radar readings no ref cites
    included, conforms; a reading changed in it breaks the seal chain at its cycle."""
    faults = Faults(profile_version="1.3", radar=True)
    path = write_profile_log(tmp_path / "p.mcap", faults=faults)
    report = doctor_log(path)
    assert report.conforms, report.errors

    def quieter(msg: RawMessage) -> bytes:
        if msg.topic == "/sensors/radar" and msg.sequence == 7:
            return b'{"targets":[{"range_m":0.6}]}'
        return msg.data

    report = doctor_log(rewrite_segment(path, tmp_path / "t.mcap", quieter))
    [chain] = [p for p in report.errors if p.rule == "seal-chain"]
    assert chain.cycle == 7 and "sensors digest" in chain.message


def test_a_1_3_seal_without_sensors_breaks_the_seal_sensors_rule(tmp_path: Path) -> None:
    faults = Faults(profile_version="1.3", seal_without_sensors_at=4)
    report = doctor_log(write_profile_log(tmp_path / "p.mcap", faults=faults))
    assert _broken(report) == {"seal-sensors"}
    [problem] = report.errors
    assert (problem.section, problem.cycle, RULES["seal-sensors"].level) == ("§6", 4, "MUST")
    # The same seal in a 1.1 segment is what that profile asks for.
    assert doctor_log(write_profile_log(tmp_path / "q.mcap", faults=Faults(radar=True))).conforms


def test_lz4_chunks_are_a_note_not_a_broken_rule(tmp_path: Path) -> None:
    report = doctor_log(write_profile_log(tmp_path / "p.mcap", faults=Faults(lz4=True)))
    assert report.conforms
    assert "chunk-compression" in {p.rule for p in report.notes}


def test_a_changed_layer_message_breaks_the_seal_chain(tmp_path: Path) -> None:
    def tamper(msg: RawMessage) -> bytes:
        if msg.topic == "/trace/action" and msg.sequence == 5:
            return msg.data.replace(b'"rejected_because":"rule"', b'"rejected_because":"RULE"')
        return msg.data

    path = write_profile_log(tmp_path / "p.mcap")
    report = doctor_log(rewrite_segment(path, tmp_path / "t.mcap", tamper))
    [chain] = [p for p in report.errors if p.rule == "seal-chain"]
    assert chain.section == "§6" and chain.cycle == 5
    assert "/trace/action" in chain.message


def test_cli_exit_codes_and_json(tmp_path: Path) -> None:
    runner = CliRunner()
    good = write_profile_log(tmp_path / "good.mcap")
    bad = write_profile_log(tmp_path / "bad.mcap", faults=Faults(log_time_off_by=1))
    ok = runner.invoke(app, ["doctor", str(good), "--plain"])
    assert ok.exit_code == 0, ok.output
    assert "CONFORMS" in ok.stdout and "cycle-in-chunk" in ok.stdout
    broken = runner.invoke(app, ["doctor", str(bad), "--json"])
    assert broken.exit_code == 1
    body = json.loads(broken.stdout)
    assert body["conforms"] is False
    [problem] = [p for p in body["segments"][0]["problems"] if p["level"] == "MUST"]
    assert (problem["rule"], problem["section"]) == ("log-time", "§4")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    unreadable = runner.invoke(app, ["doctor", str(junk)])
    assert unreadable.exit_code == 3
    assert unreadable.stderr.count("\n") == 1 and "not an MCAP file" in unreadable.stderr


def test_a_path_that_is_not_mcap_raises_log_read_error(tmp_path: Path) -> None:
    with pytest.raises(LogReadError):
        doctor_log(tmp_path / "missing.mcap")
    (tmp_path / "empty").mkdir()
    with pytest.raises(LogReadError):
        doctor_log(tmp_path / "empty")


@pytest.mark.parametrize(
    ("data", "why"),
    [
        (b'{"cycle":1,"t_ns":2,"s":"a b\\" c"}', ""),  # spaces inside strings are content
        (b'{"cycle":1, "t_ns":2}', "whitespace"),
        (b'{"cycle":1,"cycle":2}', "repeats the key 'cycle'"),
        (b'\xef\xbb\xbf{"cycle":1}', "byte-order mark"),
        (b'{"cycle":1', "not JSON"),
        (b'{"s":"\xff"}', "not UTF-8"),
    ],
)
def test_canonical_bytes_check(data: bytes, why: str) -> None:
    from trace_audit.doctor.content import parse_canonical

    _value, got = parse_canonical(data)
    assert (why in got) if why else got == ""


def test_progress_counts_bytes_up_to_the_whole_log(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root", max_segment_s=3.0)
    calls: list[tuple[int, int]] = []
    doctor_log(root, progress=lambda done, total: calls.append((done, total)))
    total = sum(p.stat().st_size for p in root.rglob("*.mcap"))
    assert calls[-1] == (total, total)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)


def test_a_summary_that_hides_a_chunk_breaks_the_summary_rule(tmp_path: Path) -> None:
    """A Chunk Index record dropped from the summary: readers that seek by the index would
    never see that chunk's cycles."""
    path = write_profile_log(tmp_path / "p.mcap")
    data = bytearray(path.read_bytes())
    # Walk the summary section (the footer says where it starts) to the second Chunk Index
    # and turn it into an unknown record type (opcode 0x80, which MCAP readers skip): the
    # file stays well-formed, the summary just no longer lists that chunk.
    summary_start = int.from_bytes(data[-8 - 20 : -8 - 12], "little")
    pos, seen = summary_start, 0
    while data[pos] != 0x08 or (seen := seen + 1) < 2:
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    data[pos] = 0x80
    path.write_bytes(bytes(data))
    report = doctor_log(path)
    summary = [p for p in report.errors if p.rule == "summary-agrees"]
    assert summary and "1 chunk(s) have no Chunk Index" in summary[0].message


def test_time_going_backwards_is_a_broken_must(tmp_path: Path) -> None:
    log = write_profile_log(tmp_path / "p.mcap", faults=Faults(clock_step_back_at=12))
    report = doctor_log(log)
    assert "time-order" in _broken(report)


# --- how a file ends, and files without chunks (found by trying rewrites from outside) -----


def _problems(report: DoctorReport, rule: str) -> list[str]:
    return [p.message for s in report.segments for p in s.problems if p.rule == rule]


def test_a_file_that_stops_between_records_is_not_called_cut_short(tmp_path: Path) -> None:
    from tests.mcap_variants import Variant, rewrite

    whole = rewrite(write_log(tmp_path / "log.mcap"), tmp_path / "copy.mcap", Variant())
    data = whole.read_bytes()
    data_end = data.index(b"\x0f\x04\x00\x00\x00\x00\x00\x00\x00", 8)  # the DataEnd record
    between = tmp_path / "between" / "log.mcap"
    between.parent.mkdir()
    between.write_bytes(data[:data_end])  # a writer stopped after its last complete record
    cut = tmp_path / "cut" / "log.mcap"
    cut.parent.mkdir()
    cut.write_bytes(data[: data_end - 5])  # a writer killed inside a record
    (stopped,) = _problems(doctor_log(between), "closed")
    assert "complete record" in stopped and "cut short" not in stopped
    (killed,) = _problems(doctor_log(cut), "closed")
    assert "cut short" in killed


def test_a_footer_without_its_closing_magic_is_not_closed(tmp_path: Path) -> None:
    source = write_log(tmp_path / "log.mcap")
    short = tmp_path / "short" / "log.mcap"
    short.parent.mkdir()
    short.write_bytes(source.read_bytes()[:-8])
    report = doctor_log(short)
    assert any("closing magic" in m for m in _problems(report, "closed"))
    assert not report.segments[0].closed


def test_messages_outside_chunks_cross_no_chunk_boundary(tmp_path: Path) -> None:
    from tests.mcap_variants import Variant, rewrite

    loose = tmp_path / "loose" / "log.mcap"
    loose.parent.mkdir()
    rewrite(write_log(tmp_path / "log.mcap"), loose, Variant(chunked=False))
    report = doctor_log(loose)
    assert report.conforms and not _problems(report, "cycle-in-chunk")
    assert report.segments[0].cycles == 100


@pytest.mark.parametrize("lz4", [False, True])
def test_a_chunk_whose_compressed_bytes_are_corrupt_is_a_problem_not_a_crash(
    tmp_path: Path, lz4: bool
) -> None:
    """Bytes flipped inside a chunk's compressed data make the decompressor itself fail
    (zstd: "Data corruption detected"; lz4: a RuntimeError), before any CRC is compared."""
    from mcap.reader import make_reader

    path = write_profile_log(tmp_path / "p.mcap", faults=Faults(lz4=lz4))
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunk = summary.chunk_indexes[len(summary.chunk_indexes) // 2]
    data = bytearray(path.read_bytes())
    at = chunk.chunk_start_offset + chunk.chunk_length * 9 // 10  # in the compressed bytes
    data[at : at + 24] = bytes(b ^ 0xFF for b in data[at : at + 24])
    path.write_bytes(bytes(data))

    report = doctor_log(path)
    readable = [p.message for p in report.errors if p.rule == "readable"]
    assert any("chunk does not decode" in message for message in readable), readable
    done = CliRunner().invoke(app, ["doctor", str(path), "--json"])
    assert done.exit_code == 1, done.exception
    assert json.loads(done.stdout)["conforms"] is False
