"""``publish --key``: the checkpoint note served must verify under one of the robot's keys
(as ``verify --key`` takes them); a note the keys did not sign publishes nothing for its
robot (exit 1); without a key the output says the signatures were not checked."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import rewrite_segment
from tests.trace_audit.publish.conftest import RobotKey
from tests.trace_audit.witness.test_tail import write
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.reading.reader import open_segment
from trace_runtime.tlog.keys import generate_keypair, load_public_key


@pytest.fixture(scope="module")
def root(tmp_path_factory: pytest.TempPathFactory, robot_key: RobotKey) -> Path:
    root = tmp_path_factory.mktemp("signed") / "root"
    write(root, robot_key.private, range(40))
    return root


@pytest.fixture(scope="module")
def stranger(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return generate_keypair(tmp_path_factory.mktemp("stranger"), name="other").public_path


def publish(root: Path, out: Path, *args: str | Path) -> tuple[int, dict[str, Any]]:
    done = cli("publish", root, "--out", out, "--json", *args)
    assert done.returncode in (0, 1), done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return done.returncode, report


def test_a_note_the_key_signed_is_published(
    root: Path, tmp_path: Path, robot_key: RobotKey
) -> None:
    code, report = publish(root, tmp_path / "out", "--key", robot_key.public)
    assert code == 0
    assert report["key_ids"] == [load_public_key(robot_key.public).key_id]
    assert report["robots"][0]["tree_size"] == 40
    assert (tmp_path / "out" / "amr-7" / "checkpoint").is_file()


def test_a_note_another_key_signed_publishes_nothing(
    root: Path, tmp_path: Path, stranger: Path
) -> None:
    out = tmp_path / "out"
    code, report = publish(root, out, "--key", stranger)
    assert code == 1
    [robot] = report["robots"]
    [problem] = robot["problems"]
    assert "not signed by the key given" in problem and "nothing published" in problem
    assert robot["tree_size"] is None
    assert not (out / "amr-7").exists()


def test_one_of_a_fleets_keys_is_enough(
    root: Path, tmp_path: Path, robot_key: RobotKey, stranger: Path
) -> None:
    code, report = publish(root, tmp_path / "out", "--key", stranger, "--key", robot_key.public)
    assert code == 0 and len(report["key_ids"]) == 2


def test_without_a_key_the_output_says_signatures_were_not_checked(
    root: Path, tmp_path: Path
) -> None:
    code, report = publish(root, tmp_path / "json")
    assert code == 0 and report["key_ids"] == []
    done = cli("publish", root, "--out", tmp_path / "plain", "--plain")
    assert done.returncode == 0, done.stderr
    assert "signatures  not checked (no --key)" in done.stdout


def test_a_key_file_that_is_not_a_key_is_one_line(root: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.pub"
    bad.write_text("not a key\n")
    one_line(cli("publish", root, "--out", tmp_path / "out", "--key", bad), 2, "bad.pub")
    assert not (tmp_path / "out").exists()


def test_a_note_whose_signature_was_changed_publishes_nothing(
    root: Path, tmp_path: Path, robot_key: RobotKey
) -> None:
    """The newest checkpoint's note, one base64 digit of its signature changed (the
    segment rewritten with the plain ``mcap`` Writer): it does not verify under the key."""
    changed = tmp_path / "changed"
    shutil.copytree(root, changed)
    last = sorted((changed / "hot").glob("*.mcap"))[-1]
    original = tmp_path / "original.mcap"
    shutil.move(last, original)
    newest = max(m.sequence for m in open_segment(original).topic_messages("/trace/checkpoint"))

    def tamper(msg: RawMessage) -> bytes:
        if msg.topic != "/trace/checkpoint" or msg.sequence != newest:
            return msg.data
        record = orjson.loads(msg.data)
        note: str = record["note"]
        at = note.rindex(" ") + 20  # a digit inside the signature's base64
        record["note"] = note[:at] + ("A" if note[at] != "A" else "B") + note[at + 1 :]
        return orjson.dumps(record)

    rewrite_segment(original, last, tamper)
    code, report = publish(changed, tmp_path / "out", "--key", robot_key.public)
    assert code == 1
    [problem] = report["robots"][0]["problems"]
    assert "signature that does not verify" in problem, problem
    assert not (tmp_path / "out" / "amr-7").exists()
    code, _report = publish(changed, tmp_path / "unchecked")  # without a key: the auditor's
    assert code == 0
