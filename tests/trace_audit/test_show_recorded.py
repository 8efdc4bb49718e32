"""What a ROS 2 robot recorded, shown: decoded messages in full (``--json``) and readably,
the region a decision cited, times in the log's clock, sensor health and staleness, and the
message an actuator channel's actual value was read from.

The recording is a rosbag2 bag written by ``rosbags`` and the log by the real
``AuditLogger`` (``tests/trace_audit/ros2_bag.py``); explain finds the bag because the log
declares it."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import orjson
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from typer.testing import CliRunner

from tests.trace_audit.ros2_bag import (
    CAMERA_BOX,
    CYCLES,
    NEAR_BEAMS,
    NEAR_M,
    PERIOD_NS,
    STALE_FROM,
    Robot,
    write_robot,
)
from trace_audit.cli import app
from trace_audit.explanation import explain
from trace_audit.readings import MAX_ITEMS, MAX_VALUES, message_data

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def robot(tmp_path_factory: pytest.TempPathFactory) -> Robot:
    return write_robot(tmp_path_factory.mktemp("ward"))


def _explain_json(log: Path, *extra: str) -> dict[str, object]:
    shown = CliRunner().invoke(app, ["explain", str(log), "--json", *extra])
    assert shown.exit_code == 0, shown.output
    data = json.loads(shown.stdout)
    assert isinstance(data, dict)
    return data


def test_json_carries_each_cited_message_decoded_in_full_with_typed_fields(robot: Robot) -> None:
    data = _explain_json(robot.log, "--cycle", "3")
    scan, camera = data["external_evidence"]  # type: ignore[misc]
    assert (scan["schema"], scan["state"]) == ("sensor_msgs/msg/LaserScan", "resolved")
    message = scan["message"]
    assert message["header"]["stamp"]["sec"] == 1_777_885_289
    assert message["header"]["frame_id"] == "base_laser"
    assert len(message["ranges"]) == 181 and message["ranges"][0] is None  # inf: no return
    assert message["ranges"][NEAR_BEAMS[0]] == NEAR_M
    assert isinstance(message["angle_increment"], float)
    [detection] = camera["message"]["detections"]
    [result] = detection["results"]
    assert result["hypothesis"] == {"class_id": "person", "score": 0.91}
    bbox = detection["bbox"]
    assert (bbox["size_x"], bbox["size_y"]) == (80.0, 200.0)
    assert bbox["center"]["position"] == {"x": 320.0, "y": 240.0}
    assert len(result["pose"]["covariance"]) == 36


def test_the_cited_region_is_read_against_the_message(robot: Robot) -> None:
    data = _explain_json(robot.log, "--cycle", "3")
    scan, camera = data["external_evidence"]  # type: ignore[misc]
    beams = scan["region"]
    assert (beams["kind"], beams["values"]) == ("beams", [80.0, 84.0])
    part = beams["part"]
    assert (part["first"], part["last"]) == NEAR_BEAMS
    assert part["ranges"] == [NEAR_M] * 5
    assert part["bearings_rad"][0] == pytest.approx(-1.5708 + 80 * 3.1416 / 180, abs=1e-6)
    box = camera["region"]
    assert box["part"]["class"] == "person" and box["part"]["overlap"] == 1.0
    assert box["part"]["box"] == list(CAMERA_BOX)


def test_explain_text_says_class_score_box_ranges_and_the_cited_beams(robot: Robot) -> None:
    shown = CliRunner().invoke(app, ["explain", str(robot.log), "--cycle", "3", "--plain"])
    assert shown.exit_code == 0, shown.output
    text = " ".join(shown.stdout.split())  # the renderer wraps long lines
    assert "person score 0.91 box 280, 140, 360, 340 (id track_7)" in text
    assert "ranges 1.250..6.000 m, nearest 1.250 m at beam 80" in text
    assert "1 beam without a return" in text
    assert "cited beams [80, 84] in base_link: beams 80..84" in text
    assert "detection person score 0.91 (box overlap 1.00)" in text
    assert "elbow: position 0.52, velocity 0.48, effort 2" in text


def test_times_are_in_the_logs_clock_never_raw_epoch_seconds(robot: Robot) -> None:
    """A wall-clock log: every time explain shows is ISO UTC (+ seconds since the start),
    the external evidence's and the chain's sensor reading's too."""
    shown = CliRunner().invoke(app, ["explain", str(robot.log), "--cycle", "3", "--plain"])
    text = " ".join(shown.stdout.split())
    assert "1777885" not in text
    assert "ward_bag /scan @ 2026-05-04T09:01:29.978Z (+0.140 s)" in text
    assert "sensor reading: ward_bag:/scan @ 2026-05-04T09:01:29.978Z" in text


def test_sensor_health_names_the_missing_sensor_and_the_stale_reading(robot: Robot) -> None:
    fresh = explain(robot.log, cycle=3)
    assert fresh.sensors is not None
    assert fresh.sensors.used == ("lidar", "head_camera")
    assert fresh.sensors.unavailable == ("wrist_camera",)
    assert [(c.sensor, c.age_ns, c.stale) for c in fresh.sensors.cited] == [
        ("lidar", 10_000_000, False),
        ("head_camera", 10_000_000, False),
        ("elbow", 10_000_000, False),
    ]
    stale_cycle = STALE_FROM + 2  # the scan stuck at cycle STALE_FROM: two periods later
    late = explain(robot.log, cycle=stale_cycle)
    assert late.sensors is not None
    lidar = late.sensors.cited[0]
    assert lidar.age_ns == 2 * PERIOD_NS + 10_000_000 and lidar.stale
    assert late.sensors.oldest_age_ns == lidar.age_ns
    assert late.sensors.stale_after_ns == PERIOD_NS * 3 // 2
    shown = CliRunner().invoke(
        app, ["explain", str(robot.log), "--cycle", str(stale_cycle), "--plain"]
    )
    text = " ".join(shown.stdout.split())
    assert "Unavailable wrist_camera" in text
    assert "ward_bag /scan (entity person_1, lidar): 110 ms old, STALE" in text
    data = _explain_json(robot.log, "--cycle", str(stale_cycle))
    assert data["sensors"]["unavailable"] == ["wrist_camera"]  # type: ignore[index]
    assert data["sensors"]["cited"][0]["stale"] is True  # type: ignore[index]


def test_an_actuator_channel_cites_the_joint_state_it_was_read_from(robot: Robot) -> None:
    result = explain(robot.log, cycle=4)
    [joint] = result.channel_evidence
    assert (joint.channel, joint.topic, joint.state) == ("elbow", "/joint_states", "resolved")
    assert joint.schema == "sensor_msgs/msg/JointState"
    assert joint.message["name"] == ["shoulder", "elbow"]
    assert joint.message["velocity"] == [0.0, 0.48]
    data = _explain_json(robot.log, "--cycle", "4")
    assert data["channel_evidence"][0]["channel"] == "elbow"  # type: ignore[index]
    assert "channel" not in data["external_evidence"][0]  # type: ignore[index]


def _altered_bag(bag: Path, into: Path, topic: str) -> Path:
    """A copy of the bag (same name) with the last bytes of every ``topic`` message flipped,
    copied message by message with the plain ``mcap`` library."""
    copy = into / bag.name
    shutil.copytree(bag, copy)
    [original] = bag.glob("*.mcap")
    with original.open("rb") as f_in, (copy / original.name).open("wb") as f_out:
        writer = Writer(f_out)
        writer.start(profile="ros2", library="test copy")
        ids: dict[int, int] = {}
        for schema, channel, message in make_reader(f_in).iter_messages():
            if channel.id not in ids:
                assert schema is not None
                sid = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid
                )
            data = message.data
            if channel.topic == topic:
                data = data[:-4] + bytes(b ^ 0xFF for b in data[-4:])
            writer.add_message(
                ids[channel.id], message.log_time, data, message.publish_time, message.sequence
            )
        writer.finish()
    return copy


def test_a_changed_joint_state_breaks_the_channels_ref(robot: Robot, tmp_path: Path) -> None:
    altered = _altered_bag(robot.bag, tmp_path, "/joint_states")
    result = explain(robot.log, cycle=4, evidence=[altered])
    [joint] = result.channel_evidence
    assert joint.state == "broken" and "digest" in joint.detail
    assert joint.message is None
    assert [e.state for e in result.external_evidence] == ["resolved", "resolved"]
    shown = CliRunner().invoke(
        app, ["explain", str(robot.log), "--cycle", "4", "--evidence", str(altered), "--plain"]
    )
    assert "elbow: actual read from ward_bag /joint_states" in " ".join(shown.stdout.split())
    assert "BROKEN" in shown.stdout


def test_logs_whose_channels_cite_nothing_read_as_before(tmp_path: Path) -> None:
    """A profile 1.0 log (no channels) and the arm example's (channels, ``ref`` null): no
    channel evidence, and the JSON has no such key."""
    v1 = _explain_json(ROOT / "tests" / "fixtures" / "v1" / "amr-fixture_000000.mcap", "--t", "+1")
    assert "channel_evidence" not in v1
    out = tmp_path / "arm.mcap"
    arm = ROOT / "examples" / "pick_and_place_arm.py"
    subprocess.run([sys.executable, str(arm), "--out", str(out)], check=True, timeout=60)
    data = _explain_json(out, "--cycle", "3")
    assert "channel_evidence" not in data
    assert data["decision"]["execution"]["channels"]  # type: ignore[index]


def test_a_message_of_any_size_is_bounded_and_says_where_it_was_cut() -> None:
    image = {"height": 1080, "data": bytes(range(256)) * 8192, "rows": [[0.5] * 2000] * 100}
    data = message_data(image)
    assert data["data"] == {"bytes": 256 * 8192, "head": bytes(range(32)).hex()}
    rows = data["rows"]
    assert rows["truncated"] is True and rows["length"] == 100
    first = rows["items"][0]
    assert first["truncated"] is True and first["length"] == 2000
    assert len(first["items"]) == MAX_ITEMS
    kept = sum(len(r["items"]) for r in rows["items"])
    assert kept <= MAX_VALUES
    assert len(orjson.dumps(data)) < 8 * MAX_VALUES
    assert message_data([math.inf, -math.inf, math.nan, 1, True]) == [None, None, None, 1, True]


def test_cycles_of_the_fixture_are_all_resolved(robot: Robot) -> None:
    """The fixture itself: every ref of every cycle resolves in the declared bag."""
    for cycle in range(CYCLES):
        result = explain(robot.log, cycle=cycle)
        states = [e.state for e in (*result.external_evidence, *result.channel_evidence)]
        assert states == ["resolved"] * 3
