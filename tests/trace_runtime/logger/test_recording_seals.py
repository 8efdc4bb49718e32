"""Every message of a recording the robot cites is sealed into its chain (profile 1.4).

From outside: the recording is a rosbag2 recording written by ``rosbags`` in another process
(``tests/rosbag_recorder.py``), the robot is the real ``AuditLogger``, the verdict is
``trace-audit verify`` run as a program, and tampering is done with ``rosbags`` too.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter

from trace_runtime import AuditLogger, EvidenceRef, LoggerConfig, Perception, external_ref
from trace_runtime.reading.recordings import Recordings
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tiers.compaction import compact

ROOT = Path(__file__).resolve().parents[3]
RECORDER = ROOT / "tests" / "rosbag_recorder.py"
from tests.outside import cli  # noqa: E402
from tests.rosbag_recorder import cdr, scan_text  # noqa: E402

FAST = {"recording_window_s": 1.0, "recording_settle_s": 0.2}


def record(bag: Path, *args: str) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, str(RECORDER), str(bag), *args], stdout=subprocess.DEVNULL
    )


def run_robot(
    root: Path,
    bag: Path,
    cycles: int,
    *,
    cited: int = 40,
    start_ns: int = 1_000_000_000,
    stamp_early_ns: int = 0,
) -> None:
    """A robot at 20 Hz (in its clock; 30 ms apart in wall time) whose first ``cited``
    cycles cite the /scan message of their time in ``bag`` (``stamp_early_ns`` before it: a
    robot that knows a message's stamp, not when its recorder received it)."""
    config = LoggerConfig(recordings=(bag,), **FAST)
    with AuditLogger(root, robot_id="ward-3", period_s=0.05, config=config) as logger:
        for i in range(cycles):
            p, b, a, e = synthetic_cycle(i)
            t_ns = start_ns + i * 50_000_000
            if i < cited:
                data = cdr(scan_text(i, 64))
                p = cite(p, external_ref(bag, "/scan", t_ns - stamp_early_ns, data))
            logger.log_cycle(t_ns, perception=p, belief=b, action=a, execution=e)
            time.sleep(0.03)


def cite(perception: Perception, ref: EvidenceRef) -> Perception:
    """The perception with its first entity's evidence citing ``ref``."""
    entity = perception.entities[0]
    evidence = entity.evidence[0].model_copy(update={"ref": ref})
    cited = entity.model_copy(update={"evidence": [evidence]})
    return perception.model_copy(update={"entities": [cited, *perception.entities[1:]]})


def verify(root: Path, *extra: str) -> tuple[int, dict[str, object]]:
    done = cli("verify", root, "--json", *extra)
    assert "Traceback" not in done.stderr, done.stderr
    return done.returncode, json.loads(done.stdout)


def kinds(report: dict[str, object], key: str) -> list[str]:
    items = report[key]
    assert isinstance(items, list)
    return [item["kind"] for item in items]


def rewrite(split: Path, change: dict[int, bytes | None], add: tuple[int, bytes] | None) -> None:
    """Rewrite one split file with the plain ``mcap`` library, as a forger would: its
    ``/odom`` message i changed (bytes) or removed (None); ``add``: one more at that time."""
    with split.open("rb") as stream:
        rows = list(make_reader(stream).iter_messages())
    with split.open("wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="ros2", library="forger")
        ids: dict[int, int] = {}
        odom = 0
        for schema, channel, message in rows:
            if channel.id not in ids:
                assert schema is not None
                schema_id = writer.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_id
                )
            data: bytes | None = message.data
            if channel.topic == "/odom":
                data = change.get(odom, data)
                odom += 1
                if add is not None and odom == 1:
                    writer.add_message(ids[channel.id], add[0], add[1], add[0])
            if data is not None:
                writer.add_message(ids[channel.id], message.log_time, data, message.publish_time)
        writer.finish()


def test_uncited_messages_in_split_files_are_sealed_and_tampering_is_named(tmp_path: Path) -> None:
    bag = tmp_path / "ward_bag"
    assert record(bag, "--splits", "3", "--messages", "60").wait(timeout=60) == 0
    root = tmp_path / "log"
    run_robot(root, bag, 70)
    code, report = verify(root)
    assert code == 0, report
    notes = kinds(report, "notes")
    assert "recording_unchecked" not in notes and "recording_unsealed" not in notes, notes
    # every recorded message, /odom that nothing cites included, is sealed and checked
    assert report["recording_messages"] == 120
    assert report["recording_checked"] == report["recording_windows"] > 0

    splits = sorted(bag.glob("*.mcap"))
    assert len(splits) == 3
    rewrite(splits[1], {2: cdr("odom forged")}, None)  # an uncited message changed
    rewrite(splits[2], {5: None}, None)  # one removed
    rewrite(splits[0], {}, (1_000_000_000 + 7 * 50_000_000 + 3_000_000, cdr("odom new")))
    code, report = verify(root)
    assert code == 1
    found = [f["message"] for f in report["findings"] if f["kind"] == "recording_modified"]
    text = " ".join(found)
    assert "1 changed: /odom" in text and "1 removed: /odom" in text, found
    assert "added in sealed windows: /odom at 1.353 s" in text, found


def test_a_recorder_killed_mid_file_is_a_declared_stall_not_tampering(tmp_path: Path) -> None:
    bag = tmp_path / "live_bag"
    # large messages, so rosbags writes a chunk every few: the file grows under the logger
    recorder = record(bag, "--messages", "400", "--hz", "40", "--size", "300000")
    root = tmp_path / "log"
    config = LoggerConfig(recordings=(bag,), **FAST)
    with AuditLogger(root, robot_id="ward-3", period_s=0.05, config=config) as logger:
        for i in range(80):
            if i == 40:
                recorder.send_signal(signal.SIGKILL)  # mid-file: no footer, a chunk cut short
                recorder.wait(timeout=10)
            p, b, a, e = synthetic_cycle(i)
            logger.log_cycle(
                1_000_000_000 + i * 50_000_000, perception=p, belief=b, action=a, execution=e
            )
            time.sleep(0.03)
    code, report = verify(root)
    assert code == 0, report["findings"]
    notes = [n["message"] for n in report["notes"] if n["kind"] == "recording_gap"]
    assert any("stalled" in n for n in notes), notes


def test_a_recording_that_never_appears_is_declared_absent(tmp_path: Path) -> None:
    root = tmp_path / "log"
    run_robot(root, tmp_path / "never_bag", 20, cited=0)
    code, report = verify(root)
    assert code == 0
    gaps = [n["message"] for n in report["notes"] if n["kind"] == "recording_gap"]
    assert gaps and "absent" in gaps[0], gaps


def test_a_root_moved_with_its_recording_finds_it_without_a_flag(tmp_path: Path) -> None:
    run = tmp_path / "run"
    bag = run / "ward_bag"
    assert record(bag, "--messages", "40").wait(timeout=60) == 0
    run_robot(run / "log", bag, 60)
    moved = tmp_path / "elsewhere"
    shutil.move(run, moved)
    code, report = verify(moved / "log")
    assert code == 0
    assert "recording_unchecked" not in kinds(report, "notes")
    # a message changed in the moved recording is found there
    rewrite(next((moved / "ward_bag").glob("*.mcap")), {3: cdr("odom forged")}, None)
    code, _ = verify(moved / "log")
    assert code == 1


@pytest.mark.parametrize("tier", ["warm", "cold"])
def test_the_windows_stay_checkable_after_compaction(tmp_path: Path, tier: str) -> None:
    bag = tmp_path / "ward_bag"
    assert record(bag, "--messages", "40").wait(timeout=60) == 0
    root = tmp_path / "log"
    run_robot(root, bag, 60)
    compact(root, tier, older_than_ns=0, sources=["hot"])
    assert not list((root / "hot").glob("*.mcap"))
    code, report = verify(root)
    assert code == 0, report["findings"]
    assert "recording_unchecked" not in kinds(report, "notes")
    rewrite(next(bag.glob("*.mcap")), {30: None}, None)
    code, report = verify(root)
    assert code == 1
    assert any("1 removed: /odom" in f["message"] for f in report["findings"]), report["findings"]


def test_a_ref_by_header_stamp_resolves_by_its_digest_near_the_recorded_time(
    tmp_path: Path,
) -> None:
    """The robot knows a message's stamp, not when its recorder received it: a ref 4 ms
    early with the message's digest resolves (the digest says which message), one with
    another digest does not."""
    bag = tmp_path / "ward_bag"
    assert record(bag, "--messages", "10").wait(timeout=60) == 0
    recordings = Recordings.open([bag])
    data = cdr(scan_text(3, 64))
    recorded = 1_000_000_000 + 3 * 50_000_000
    early = external_ref(bag, "/scan", recorded - 4_000_000, data)
    check = recordings.check(early.model_dump())
    assert check.state == "resolved" and check.message is not None
    assert check.message.log_time_ns == recorded and check.shift_ns == 4_000_000
    wrong = external_ref(bag, "/scan", recorded - 4_000_000, cdr("not recorded"))
    assert recordings.check(wrong.model_dump()).state == "broken"


def test_a_bag_kept_inside_the_root_is_a_recording_not_a_foreign_file(tmp_path: Path) -> None:
    root = tmp_path / "log"
    bag = root / "recordings" / "ward_bag"
    assert record(bag, "--messages", "20").wait(timeout=60) == 0
    run_robot(root, bag, 40, cited=20)
    code, report = verify(root)
    assert code == 0, report["findings"]
    assert "skipped_file" not in kinds(report, "notes")
    assert "recording_unchecked" not in kinds(report, "notes")
