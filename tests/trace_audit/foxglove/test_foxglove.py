"""``trace-audit export --format foxglove``, read back with the reference ``mcap`` reader and
decoded with the SDK's own protobuf schemas."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import orjson
import pytest
from mcap.reader import make_reader

from tests.outside import REPO, cli
from tests.trace_audit.conftest import write_log
from trace_audit.transitions import timeline

pytest.importorskip("foxglove")

from foxglove.messages import Log as FoxLog
from foxglove.messages import SceneUpdate


def _messages(path: Path) -> list[tuple[Any, Any, Any]]:
    with path.open("rb") as f:
        return list(make_reader(f).iter_messages(log_time_order=False))


def _holds_position(data: bytes, xyz: list[float]) -> bool:
    """Whether a protobuf message holds this x, y, z: a double is its 8 little-endian bytes
    (proto3 leaves a 0.0 out), so each coordinate's bytes are in the message."""
    return all(struct.pack("<d", v) in data for v in xyz if v != 0.0)


def _export(log: Path, out: Path, *args: str) -> None:
    done = cli("export", log, "--format", "foxglove", "--out", out, *args)
    assert done.returncode == 0, done.stderr


def test_the_export_is_foxglove_and_still_a_trace_log(tmp_path: Path) -> None:
    log = write_log(tmp_path / "root", max_segment_s=3.0)  # four segments
    out = tmp_path / "view.mcap"
    _export(log, out)
    messages = _messages(out)
    by_topic: dict[str, list[tuple[Any, Any, Any]]] = {}
    for schema, channel, message in messages:
        by_topic.setdefault(channel.topic, []).append((schema, channel, message))
    scene_schema = by_topic["/foxglove/scene"][0][0]
    assert (scene_schema.name, scene_schema.encoding) == ("foxglove.SceneUpdate", "protobuf")
    assert by_topic["/foxglove/scene"][0][1].message_encoding == "protobuf"
    log_schema = by_topic["/foxglove/decisions"][0][0]
    assert (log_schema.name, log_schema.encoding) == ("foxglove.Log", "protobuf")
    assert scene_schema.data == SceneUpdate.get_schema().data
    assert by_topic["/foxglove/factors"][0][1].message_encoding == "json"

    original = [m for p in sorted(log.rglob("*.mcap")) for m in _messages(p)]
    trace = [(c.topic, m.sequence, m.log_time, m.data) for _, c, m in original]
    copied = [
        (c.topic, m.sequence, m.log_time, m.data)
        for _, c, m in messages
        if c.topic.startswith(("/trace/", "/sensors/"))
    ]
    assert sorted(copied) == sorted(
        t
        for t in trace
        if t[0].startswith(("/trace/", "/sensors/")) and t[0] != "/trace/checkpoint"
    )
    assert "CLEAN" in cli("verify", out).stdout

    cycles = {m.log_time for _, c, m in original if c.topic == "/trace/seal"}
    scenes = by_topic["/foxglove/scene"]
    assert sorted(m.log_time for _, _, m in scenes) == sorted(cycles)  # one per cycle
    perceptions = {
        m.log_time: orjson.loads(m.data) for _, c, m in original if c.topic == "/trace/perception"
    }
    for _, _, message in scenes:
        for entity in perceptions[message.log_time]["entities"]:
            assert entity["id"].encode() in message.data
            assert _holds_position(message.data, entity["pose"]["position"]), entity
        assert b"evidence verified" in message.data or b"evidence FAILED" in message.data

    rows = timeline(log).rows
    logs = [m.data for _, _, m in by_topic["/foxglove/decisions"]]
    assert len(logs) == len(rows)
    for row, entry in zip(rows, logs, strict=True):
        assert f"cycle {row.cycle}: ".encode() in entry and str(row.command).encode() in entry
    assert FoxLog.get_schema().name == "foxglove.Log"


def test_a_window_exports_only_its_cycles_and_still_verifies(tmp_path: Path) -> None:
    log = write_log(tmp_path / "root", max_segment_s=3.0)
    out = tmp_path / "window.mcap"
    _export(log, out, "--from", "103.05", "--to", "106")
    seals = [m for _, c, m in _messages(out) if c.topic == "/trace/seal"]
    assert seals[0].log_time == 103_100_000_000 and len(seals) == 30
    assert "CLEAN" in cli("verify", out).stdout


def test_an_existing_file_or_no_out_is_refused(tmp_path: Path) -> None:
    log = write_log(tmp_path / "run.mcap")
    out = tmp_path / "view.mcap"
    out.write_bytes(b"mine")
    taken = cli("export", log, "--format", "foxglove", "--out", out)
    assert taken.returncode == 4 and out.read_bytes() == b"mine", taken.stderr
    no_out = cli("export", log, "--format", "foxglove")
    assert no_out.returncode == 2 and "--out" in no_out.stderr


def test_an_arm_log_exports_without_planar_fields(tmp_path: Path) -> None:
    arm = tmp_path / "arm"
    made = subprocess.run(
        [sys.executable, str(REPO / "examples" / "pick_and_place_arm.py"), "--out", str(arm)],
        capture_output=True,
        text=True,
        check=False,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    assert made.returncode == 0, made.stderr
    out = tmp_path / "arm.mcap"
    _export(arm, out)
    messages = _messages(out)
    topics = {c.topic for _, c, _ in messages}
    assert {"/foxglove/scene", "/foxglove/decisions", "/foxglove/actuators"} <= topics
    actuators = [orjson.loads(m.data) for _, c, m in messages if c.topic == "/foxglove/actuators"]
    names = set().union(*(a.keys() for a in actuators))
    assert names - {"deviation"}, names  # the arm's own joint channels, by their names
    assert not {"linear", "angular", "x", "y"} & names
    assert "CLEAN" in cli("verify", out).stdout


@pytest.mark.parametrize("option", [("--t", "105"), ("--cycle", "50")])
def test_one_decision_options_are_refused_for_a_window_export(
    tmp_path: Path, option: tuple[str, str]
) -> None:
    log = write_log(tmp_path / "run.mcap")
    out = tmp_path / "view.mcap"
    done = cli("export", log, "--format", "foxglove", "--out", out, *option)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "--from/--to" in done.stderr, done.stderr
    assert option[0] in done.stderr and not out.exists()


def _verified(out: Path) -> tuple[int, list[dict[str, Any]], list[str]]:
    done = cli("verify", out, "--json")
    report = orjson.loads(done.stdout)
    return done.returncode, report["findings"], [n["kind"] for n in report["notes"]]


def test_windowed_exports_verify_as_docs_foxglove_says(tmp_path: Path) -> None:
    """A window from a later segment verifies clean (its chain starts as after retention, a
    note); one from the start is clean; one cut inside a segment is an excerpt: clean, with
    a note naming where it was cut."""
    file = write_log(tmp_path / "run.mcap")
    root = write_log(tmp_path / "root", max_segment_s=5.0)  # segments 0 and 1 (from 105 s)
    assert len(list(root.rglob("*.mcap"))) == 2

    later = tmp_path / "later.mcap"
    _export(root, later, "--from", "106", "--to", "108")
    code, findings, notes = _verified(later)
    assert (code, findings) == (0, []) and "chain_start" in notes

    for log in (file, root):
        head = tmp_path / f"head-{log.name}.mcap"
        _export(log, head, "--to", "103")
        assert _verified(head)[:2] == (0, [])

        inside = tmp_path / f"inside-{log.name}.mcap"
        _export(log, inside, "--from", "102")
        code, findings, notes = _verified(inside)
        assert (code, findings) == (0, []) and "chain_start" in notes
        said = orjson.loads(cli("verify", inside, "--json").stdout)["notes"]
        assert any("excerpt from cycle 20" in n["message"] for n in said), said


def test_an_excerpt_with_a_cycle_changed_is_still_found(tmp_path: Path) -> None:
    """The excerpt record moves where the chain starts, nothing else: a cycle changed in
    the excerpt is still a finding."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    inside = tmp_path / "inside.mcap"
    _export(write_log(tmp_path / "run.mcap"), inside, "--from", "102")
    tampered = tmp_path / "tampered.mcap"
    with inside.open("rb") as src, tampered.open("wb") as dst:
        reader = make_reader(src)
        writer = Writer(dst)
        writer.start(profile="trace", library="tests")
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, record.metadata)
        ids: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages():
            if channel.id not in ids:
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid
                )
            data = message.data
            if channel.topic == "/trace/action" and message.sequence == 30:
                data = data.replace(b"STOP", b"SLOW") if b"STOP" in data else data + b" "
            writer.add_message(
                ids[channel.id], message.log_time, data, message.publish_time, message.sequence
            )
        writer.finish()
    code, findings, _ = _verified(tampered)
    assert code == 1 and any(f.get("first_cycle") == 30 for f in findings), findings


def test_a_gap_is_a_warning_in_the_log_panel_before_the_change_after_it(tmp_path: Path) -> None:
    # cycles 20..39 dropped (2 s at 10 Hz); cycle 40 is the first STOP
    log = write_log(tmp_path / "root", skip=lambda i: 20 <= i < 40)
    out = tmp_path / "view.mcap"
    _export(log, out)
    with out.open("rb") as f:
        entries = [
            m.data
            for _, channel, m in make_reader(f).iter_messages()
            if channel.topic == "/foxglove/decisions"
        ]
    (gap,) = [i for i, data in enumerate(entries) if b"GAP after cycle 19: 20 cycles" in data]
    assert b"cycle 40: " in entries[gap + 1]  # the change after it comes next
    assert b"2.000 s) not logged" in entries[gap]
