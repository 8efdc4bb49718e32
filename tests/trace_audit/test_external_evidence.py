"""Evidence refs into an external rosbag2-style MCAP recording (PROFILE.md section 11).

The recording is a real ROS 2 MCAP written by ``mcap-ros2-support`` (file_recording_robot.py,
the example robot before issue 42: one file, cited by file name and sequence, not declared):
``sensor_msgs/msg/LaserScan`` with its ``ros2msg`` schema, CDR messages. The TRACE log cites
its messages; explain, verify, metrics and doctor resolve them when given the recording,
check their digests, and keep "recording not given" apart from "broken"."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from typer.testing import CliRunner

from trace_audit.cli import app
from trace_audit.doctor import doctor_log
from trace_audit.explanation import explain
from trace_audit.metrics import MetricsConfig, compute_metrics
from trace_audit.verify import verify_log
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.reading.recordings import Recordings

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "tests" / "trace_audit" / "file_recording_robot.py"
CYCLES = 40


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(TRACE log, rosbag2 directory) written by the robot, as a user would run it."""
    out = tmp_path_factory.mktemp("ros2") / "robot.mcap"
    subprocess.run(
        [sys.executable, str(EXAMPLE), "--out", str(out), "--cycles", str(CYCLES)],
        check=True,
        cwd=ROOT,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        timeout=60,
    )
    return out, out.with_name("robot_bag")


def _copy_bag(
    src: Path,
    dst: Path,
    change: int | None = None,
    drop: int | None = None,
    stop: int | None = None,
) -> Path:
    """Copy a recording message by message; flip a byte of message ``change``, leave out
    message ``drop`` and every message from ``stop`` on (by sequence): what a damaged, edited
    or cut-short recording looks like."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    with src.open("rb") as f_in, dst.open("wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out)
        writer.start(profile="ros2", library="test copy")
        ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages():
            if channel.id not in ids:
                assert schema is not None
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid
                )
            if message.sequence == drop or (stop is not None and message.sequence >= stop):
                continue
            data = message.data
            if message.sequence == change:
                data = data[:-8] + bytes(b ^ 0xFF for b in data[-8:])
            writer.add_message(
                ids[channel.id], message.log_time, data, message.publish_time, message.sequence
            )
        writer.finish()
    return dst


def test_the_recording_is_a_real_ros2_mcap_that_mcap_ros2_decodes(robot: tuple[Path, Path]) -> None:
    from mcap_ros2.decoder import DecoderFactory

    _log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    with recording.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        decoded = list(reader.iter_decoded_messages())
    assert len(decoded) == CYCLES
    schema, channel, _message, scan = decoded[0]
    assert (schema.name, schema.encoding, channel.message_encoding) == (
        "sensor_msgs/msg/LaserScan",
        "ros2msg",
        "cdr",
    )
    assert len(scan.ranges) == 32 and scan.header.frame_id == "base_laser"


def test_verify_checks_the_digests_only_when_given_the_recording(robot: tuple[Path, Path]) -> None:
    log, bag = robot
    alone = verify_log(log)
    assert alone.ok
    assert (alone.external_resolved, alone.external_unresolved) == (0, CYCLES)
    assert [n.kind for n in alone.notes].count("external_unresolved") == 1
    given = verify_log(log, evidence=[bag])
    assert given.ok
    assert (given.external_resolved, given.external_unresolved) == (CYCLES, 0)
    assert "external_unresolved" not in [n.kind for n in given.notes]


def test_a_changed_or_missing_message_in_the_recording_is_a_finding(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    changed = _copy_bag(recording, tmp_path / "changed" / recording.name, change=10)
    report = verify_log(log, evidence=[changed])
    assert not report.ok
    [finding] = report.findings
    assert finding.kind == "evidence_mismatch" and finding.where.first_cycle == 10
    assert "does not match the ref's digest" in finding.message
    assert report.external_resolved == CYCLES - 1

    dropped = _copy_bag(recording, tmp_path / "dropped" / recording.name, drop=7)
    [finding] = verify_log(log, evidence=[dropped]).findings
    assert finding.where.first_cycle == 7 and "no /scan message" in finding.message


def test_a_recording_cut_short_is_one_finding_for_the_run_of_cycles_it_lost(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    """Every missing message is real missing evidence, but 15 identical findings bury the
    one fact: the recording ends at cycle 24. One finding spans the run, with its count."""
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    cut = _copy_bag(recording, tmp_path / "cut" / recording.name, stop=25, drop=10)
    report = verify_log(log, evidence=[cut])
    spans = sorted((f.kind, f.where.first_cycle, f.where.last_cycle) for f in report.findings)
    assert spans == [("evidence_mismatch", 10, 10), ("evidence_mismatch", 25, CYCLES - 1)]
    run = max(report.findings, key=lambda f: f.where.last_cycle or 0)
    assert f"{CYCLES - 25} evidence refs" in run.message
    assert "no /scan message" in run.message and recording.name in run.message
    assert report.cycles_valid == CYCLES - 1 - (CYCLES - 25)


def test_one_missing_message_is_said_plainly_and_a_run_as_a_run(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    """The words "the first" and "a run of them" only fit when several refs are missing."""
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    cut = _copy_bag(recording, tmp_path / "cut" / recording.name, stop=25, drop=10)
    one, run = sorted(
        verify_log(log, evidence=[cut]).findings, key=lambda f: f.where.first_cycle or 0
    )
    assert one.message.startswith(
        f"cycle 10: an evidence ref names a message that external recording {recording.name} "
        "does not hold: no /scan message"
    )
    assert "the first" not in one.message and "a run of them" not in one.message
    assert run.message.startswith(f"cycles 25..{CYCLES - 1}: {CYCLES - 25} evidence refs name")
    assert "(the first: no /scan message" in run.message and "cut short" in run.message


def test_doctor_breaks_external_digest_for_refs_the_recording_does_not_hold(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    """PROFILE section 11: "the message is not there" breaks the rule as a changed message
    does. A cut recording is one problem for its run of cycles (not one per ref), located
    by its cycle range, and a changed message before the cut stays a problem of its own."""
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    damaged = _copy_bag(recording, tmp_path / "d" / recording.name, change=5, drop=10, stop=25)
    report = doctor_log(log, evidence=[damaged])
    assert not report.conforms
    located = [(p.rule, p.section, p.cycle, p.last_cycle, p.count) for p in report.errors]
    assert located == [
        ("external-digest", "§11", 5, 5, 1),
        ("external-digest", "§11", 10, 10, 1),
        ("external-digest", "§11", 25, CYCLES - 1, 1),
    ]
    changed, dropped, cut = report.errors
    assert "does not match the ref's digest" in changed.message
    assert "no /scan message" in dropped.message
    assert f"{CYCLES - 25} evidence refs" in cut.message and recording.name in cut.message

    runner = CliRunner()
    shown = runner.invoke(app, ["doctor", str(log), "--evidence", str(damaged), "--plain"])
    assert shown.exit_code == 1, shown.output
    assert "CONFORMS" not in shown.stdout and f"cycles 25..{CYCLES - 1}" in shown.stdout


def test_verify_on_worker_processes_checks_the_recording_there_too(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    """``--scheduler`` and ``--evidence`` together: each worker re-opens the recordings by
    absolute path, so a changed message is the same finding as in a local run."""
    from concurrent.futures import ProcessPoolExecutor

    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    changed = _copy_bag(recording, tmp_path / "changed" / recording.name, change=10)
    local = verify_log(log, evidence=[changed])
    with ProcessPoolExecutor(max_workers=1) as pool:
        remote = verify_log(log, evidence=[changed], executor=pool)
    assert [(f.kind, f.where.first_cycle) for f in remote.findings] == [("evidence_mismatch", 10)]
    assert (remote.external_resolved, remote.ok) == (local.external_resolved, local.ok)
    assert [f.message for f in remote.findings] == [f.message for f in local.findings]


def test_a_recording_not_given_is_unresolved_not_broken(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    other = _copy_bag(recording, tmp_path / "other_bag" / "other_bag_0.mcap")
    report = verify_log(log, evidence=[other])
    assert report.ok and (report.external_resolved, report.external_unresolved) == (0, CYCLES)
    metrics = compute_metrics([log], MetricsConfig(evidence=(str(other),)))
    assert metrics.external_refs == {"unresolved": CYCLES}


def test_metrics_count_resolved_broken_and_unresolved_apart(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    without = compute_metrics([log])
    given = compute_metrics([log], MetricsConfig(evidence=(str(bag),)))
    assert without.external_refs == {"unresolved": CYCLES}
    assert given.external_refs == {"resolved": CYCLES}
    # not checked is unknown, not 0: those decisions are counted apart
    assert without.overall.et.mean is None and without.overall.unknown == CYCLES
    assert given.overall.et.mean == 1.0 and given.overall.unknown == 0
    changed = _copy_bag(recording, tmp_path / "c" / recording.name, change=3)
    broken = compute_metrics([log], MetricsConfig(evidence=(str(changed),)))
    assert broken.external_refs == {"broken": 1, "resolved": CYCLES - 1}


def test_explain_resolves_and_decodes_the_cited_scan(robot: tuple[Path, Path]) -> None:
    log, bag = robot
    result = explain(log, cycle=5, evidence=[bag])
    [external] = result.external_evidence
    assert external.state == "resolved" and external.schema == "sensor_msgs/msg/LaserScan"
    assert len(external.message["ranges"]) == 32
    assert external.lines[0].startswith("32 beams from")
    assert all(c.traceable for c in result.chains.factors)
    unchecked = explain(log, cycle=5)
    assert [e.state for e in unchecked.external_evidence] == ["unresolved"]
    [chain] = unchecked.chains.factors
    assert chain.missing is not None and "not given" in chain.missing.detail


def test_cli_evidence_option_and_exit_codes(robot: tuple[Path, Path], tmp_path: Path) -> None:
    log, bag = robot
    runner = CliRunner()
    shown = runner.invoke(app, ["explain", str(log), "--cycle", "5", "--evidence", str(bag)])
    assert shown.exit_code == 0, shown.output
    assert "resolved, digest verified" in shown.stdout
    assert "sensor_msgs/msg/LaserScan" in shown.stdout
    [recording] = list(bag.glob("*.mcap"))
    changed = _copy_bag(recording, tmp_path / "c" / recording.name, change=2)
    failed = runner.invoke(app, ["verify", str(log), "--evidence", str(changed), "--json"])
    assert failed.exit_code == 1
    assert json.loads(failed.stdout)["findings"][0]["kind"] == "evidence_mismatch"
    missing = runner.invoke(app, ["verify", str(log), "--evidence", str(tmp_path / "nope")])
    assert missing.exit_code == 3 and "no such recording" in missing.stderr
    doctor = runner.invoke(app, ["doctor", str(log), "--evidence", str(changed), "--json"])
    assert doctor.exit_code == 1
    [problem] = [
        p for p in json.loads(doctor.stdout)["segments"][0]["problems"] if p["level"] == "MUST"
    ]
    assert (problem["rule"], problem["section"]) == ("external-digest", "§11")


def test_doctor_passes_the_ros2_robot_and_notes_unchecked_refs(robot: tuple[Path, Path]) -> None:
    log, bag = robot
    alone = doctor_log(log)
    assert alone.conforms
    assert [p.rule for p in alone.notes] == ["external-given"]
    assert doctor_log(log, evidence=[bag]).notes == []


def test_recordings_refuse_a_file_that_is_not_mcap(tmp_path: Path) -> None:
    bad = tmp_path / "x_0.mcap"
    bad.write_bytes(b"not mcap")
    recordings = Recordings.open([bad])
    with pytest.raises(LogReadError):
        recordings.check({"recording": "x_0.mcap", "topic": "/scan", "log_time_ns": 1})


def test_the_incident_report_resolves_the_recording_when_given_it(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    """``report --evidence``: the same resolution as explain, metrics and verify, shown in
    the page, and the reproduce commands carry the recording."""
    from trace_audit.incident import build_report

    log, bag = robot
    without = build_report(log, cycle=10)
    given = build_report(log, cycle=10, evidence=[bag])
    assert {e.state for e in without.data.explanation.external_evidence} == {"unresolved"}
    assert {e.state for e in given.data.explanation.external_evidence} == {"resolved"}
    assert "not checked, unknown" in without.html and "robot_bag_0.mcap not given" in without.html
    assert "resolved, digest matches" in given.html and "LaserScan" in given.html
    assert f"--evidence {bag}" in given.html
    assert given.data.metrics.external_refs.get("resolved", 0) >= 1
    assert given.data.integrity.external_resolved >= 1 and given.data.integrity.ok
    [recording] = list(bag.glob("*.mcap"))
    changed = _copy_bag(recording, tmp_path / "c" / recording.name, change=10)
    broken = build_report(log, cycle=10, evidence=[changed])
    assert {e.state for e in broken.data.explanation.external_evidence} == {"broken"}
    assert not broken.data.integrity.ok


def test_two_recordings_of_one_name_are_refused_not_checked_against_either(
    robot: tuple[Path, Path], tmp_path: Path
) -> None:
    """An altered copy given beside the intact bag must not pass because the intact one
    matches: the name is ambiguous, so the command says so (exit 2)."""
    log, bag = robot
    [recording] = list(bag.glob("*.mcap"))
    altered = _copy_bag(recording, tmp_path / "bad_bag" / recording.name, change=10)
    with pytest.raises(UsageError, match="two recordings named"):
        Recordings.open([altered.parent, bag])
    result = CliRunner().invoke(
        app, ["verify", str(log), "--evidence", str(altered.parent), "--evidence", str(bag)]
    )
    assert result.exit_code == 2, result.output
    assert "two recordings named" in result.stderr
    # the same file given twice (as a file and inside its directory) is one recording, known
    # by its own name and by its bag's
    assert Recordings.open([recording, bag]).names == sorted([bag.name, recording.name])
