"""The Foxglove export decoded as Foxglove decodes it: each message by the protobuf
``FileDescriptorSet`` its schema record carries (the SDK's own), with ``google.protobuf``,
and every value compared with the log's own JSON, read with the reference ``mcap`` reader."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson
import pytest
from mcap.reader import make_reader

from tests.outside import REPO, cli
from tests.trace_audit.conftest import write_log
from trace_runtime.chain import digest

pytest.importorskip("foxglove")
pytest.importorskip("google.protobuf")

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import Message

FOXGLOVE_SCHEMAS = {
    "/foxglove/scene": "foxglove.SceneUpdate",
    "/foxglove/robot_pose": "foxglove.PoseInFrame",
    "/foxglove/decisions": "foxglove.Log",
}


def _decoder(schema: Any) -> Callable[[bytes], Message]:
    """The protobuf class of a schema record, built from the descriptors in its data alone."""
    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    waiting = list(files.file)
    while waiting:  # a file is added once the files it imports are in the pool
        added = []
        for file in waiting:
            if all(_has_file(pool, dep) for dep in file.dependency):
                pool.Add(file)
                added.append(file)
        assert added, [f.name for f in waiting]  # every import is in the set
        waiting = [f for f in waiting if f not in added]
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return cls.FromString


def _has_file(pool: descriptor_pool.DescriptorPool, name: str) -> bool:
    try:
        pool.FindFileByName(name)
    except KeyError:
        return False
    return True


class _Read:
    """An export as read back: each channel's messages, the Foxglove ones decoded."""

    def __init__(self, path: Path) -> None:
        self.schemas: dict[str, tuple[str, str, str]] = {}
        self.decoded: dict[str, list[tuple[int, Message]]] = {}
        self.json: dict[str, list[tuple[int, Any]]] = {}
        decoders: dict[int, Callable[[bytes], Message]] = {}
        with path.open("rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
                topic = channel.topic
                self.schemas[topic] = (schema.name, schema.encoding, channel.message_encoding)
                if channel.message_encoding == "protobuf":
                    decode = decoders.get(channel.id)
                    if decode is None:
                        decode = decoders[channel.id] = _decoder(schema)
                    found = decode(message.data)
                    self.decoded.setdefault(topic, []).append((message.log_time, found))
                elif topic.startswith("/foxglove/"):
                    self.json.setdefault(topic, []).append(
                        (message.log_time, orjson.loads(message.data))
                    )


def _original(log: Path) -> list[tuple[str, int, int, bytes]]:
    """Every message of a log's segments: topic, sequence, log time, data."""
    found = []
    for path in sorted(log.rglob("*.mcap")) if log.is_dir() else [log]:
        with path.open("rb") as f:
            for _, channel, m in make_reader(f).iter_messages(log_time_order=False):
                found.append((channel.topic, m.sequence, m.log_time, m.data))
    return found


def _layers(original: list[tuple[str, int, int, bytes]], topic: str) -> dict[int, Any]:
    return {t: orjson.loads(d) for top, _, t, d in original if top == topic}


def _export(log: Path, out: Path) -> _Read:
    done = cli("export", log, "--format", "foxglove", "--out", out)
    assert done.returncode == 0, done.stderr
    return _Read(out)


def _xyz(pose: Any) -> tuple[float, float, float]:
    return (pose.position.x, pose.position.y, pose.position.z)


def test_the_export_decodes_with_the_sdks_descriptors_to_the_logs_values(
    tmp_path: Path,
) -> None:
    # a robot id with "_" in it, as a segment name's robot part may hold
    log = write_log(tmp_path / "root", max_segment_s=3.0, robot_id="amr_7")
    read = _export(log, tmp_path / "view.mcap")
    original = _original(log)

    for topic, name in FOXGLOVE_SCHEMAS.items():
        if topic in read.schemas:
            assert read.schemas[topic] == (name, "protobuf", "protobuf"), topic
    assert {"/foxglove/scene", "/foxglove/decisions"} <= set(read.decoded)

    # one SceneUpdate per cycle, at the cycle's time
    seals = _layers(original, "/trace/seal")
    scenes = read.decoded["/foxglove/scene"]
    assert sorted(t for t, _ in scenes) == sorted(seals)
    assert len({t for t, _ in scenes}) == len(scenes)

    # each perceived entity with a position, where the log puts it, labelled as logged
    sensors = {(top, seq, t): digest(d) for top, seq, t, d in original if top.startswith("/sen")}
    perceptions = _layers(original, "/trace/perception")
    for t_ns, update in scenes:
        assert [d.type for d in update.deletions] == [1]  # ALL: the last cycle's go first
        shown = {e.id: e for e in update.entities}
        logged = [e for e in perceptions[t_ns]["entities"] if e.get("pose")]
        assert set(shown) == {e["id"] for e in logged}
        for entity in logged:
            scene = shown[entity["id"]]
            assert scene.timestamp.seconds * 10**9 + scene.timestamp.nanos == t_ns
            assert scene.frame_id == entity["pose"]["frame"]
            assert _xyz(scene.cubes[0].pose) == tuple(entity["pose"]["position"])
            refs = [e["ref"] for e in entity["evidence"]]
            verified = bool(refs) and all(
                r is not None
                and sensors.get((r["topic"], r["sequence"], r["log_time_ns"])) == r["digest"]
                for r in refs
            )
            cls = entity["class"]
            label = f"{entity['id']}: {cls} {entity['confidence'][cls]:.2f}, evidence "
            label += "verified" if verified else "FAILED"
            assert scene.texts[0].text == label
            green = scene.cubes[0].color.g > scene.cubes[0].color.r
            assert green == verified, label
    assert any("FAILED" in e.texts[0].text for _, u in scenes for e in u.entities)

    # every decision change, as a Log message at its cycle's time
    actions = _layers(original, "/trace/action")
    changes, previous = [], None
    for t_ns in sorted(actions):
        command = actions[t_ns]["command"]
        if command != previous:
            changes.append((t_ns, actions[t_ns]["cycle"], previous, command))
        previous = command
    logs = read.decoded["/foxglove/decisions"]
    assert len(logs) == len(changes)
    for (t_ns, entry), (when, cycle, was, command) in zip(logs, changes, strict=True):
        assert t_ns == when and entry.line == cycle and entry.name == "amr_7"
        assert entry.level == 2  # INFO
        assert entry.file.startswith("amr_7_") and entry.file.endswith(".mcap")
        assert entry.timestamp.seconds * 10**9 + entry.timestamp.nanos == when
        change = f"{was} -> {command}" if was is not None else command
        assert entry.message.startswith(f"cycle {cycle}: {change}"), entry.message
        rationale = actions[when]["rationale"]["text"]
        assert entry.message.endswith(f"because {rationale}"), entry.message

    # the plot channels: each numeric factor by name, the execution's deviation
    factors = dict(read.json["/foxglove/factors"])
    assert sorted(factors) == sorted(seals)
    for t_ns, action in actions.items():
        expected = {
            f["name"] or f["node"]: float(f["value"])
            for f in action["rationale"]["factors"]
            if isinstance(f["value"], int | float) and not isinstance(f["value"], bool)
        }
        assert factors[t_ns] == expected, t_ns
    actuators = dict(read.json["/foxglove/actuators"])
    for t_ns, execution in _layers(original, "/trace/execution").items():
        assert actuators[t_ns]["deviation"] == execution["deviation"]


def test_an_arm_exports_its_joint_channels_and_no_planar_fields(tmp_path: Path) -> None:
    arm = tmp_path / "arm"
    made = subprocess.run(
        [sys.executable, str(REPO / "examples" / "pick_and_place_arm.py"), "--out", str(arm)],
        capture_output=True,
        text=True,
        check=False,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    assert made.returncode == 0, made.stderr
    read = _export(arm, tmp_path / "arm.mcap")
    original = _original(arm)
    scenes = read.decoded["/foxglove/scene"]
    assert len(scenes) == len(_layers(original, "/trace/seal"))
    perceptions = _layers(original, "/trace/perception")
    for t_ns, update in scenes:
        logged = {e["id"] for e in perceptions[t_ns]["entities"] if e.get("pose")}
        robot = perceptions[t_ns].get("robot_pose") is not None
        assert {e.id for e in update.entities} == logged | ({"robot"} if robot else set())
    actuators = dict(read.json["/foxglove/actuators"])
    for t_ns, execution in _layers(original, "/trace/execution").items():
        plotted = actuators[t_ns]
        for channel in execution["channels"]:
            assert plotted[channel["name"]] == {
                "intended": channel["intended"],
                "actual": channel["actual"],
                "deviation": channel["deviation"],
            }
        assert not {"linear", "angular"} & set(plotted)


def test_a_robot_that_logs_its_pose_is_shown_where_it_logged_it(tmp_path: Path) -> None:
    sim = tmp_path / "sim"
    run = ["run", "--duration", "10s", "--seed", "1", "--out", str(sim)]
    made = subprocess.run(
        [sys.executable, "-c", "from evaluation.cli import main; main()", *run],
        capture_output=True,
        text=True,
        check=False,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    assert made.returncode == 0, made.stderr
    read = _export(sim, tmp_path / "sim.mcap")
    assert read.schemas["/foxglove/robot_pose"] == ("foxglove.PoseInFrame", "protobuf", "protobuf")
    perceptions = _layers(_original(sim), "/trace/perception")
    poses = dict(read.decoded["/foxglove/robot_pose"])
    logged = {t: p["robot_pose"] for t, p in perceptions.items() if p.get("robot_pose")}
    assert logged and sorted(poses) == sorted(logged)
    for t_ns, update in read.decoded["/foxglove/scene"]:
        pose = logged[t_ns]
        shown = poses[t_ns]
        assert shown.frame_id == pose["frame"]
        assert _xyz(shown.pose) == tuple(pose["position"])
        q = shown.pose.orientation
        assert (q.x, q.y, q.z, q.w) == tuple(pose["orientation"])
        robot = next(e for e in update.entities if e.id == "robot")
        assert _xyz(robot.cubes[0].pose) == tuple(pose["position"])
        assert robot.texts[0].text == "robot"
