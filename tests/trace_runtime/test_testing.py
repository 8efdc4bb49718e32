"""CaptureLogger lets integrators unit-test their robots with no files."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.chain import digest
from trace_runtime.testing import CaptureLogger, synthetic_cycle

ROOT = Path(__file__).resolve().parents[2]


def test_capture_seals_exactly_like_the_file_logger(tmp_path: Path) -> None:
    capture = CaptureLogger(robot_id="r")
    path = tmp_path / "same.mcap"
    with AuditLogger(path, robot_id="r", config=LoggerConfig(threaded=False)) as real:
        for sink in (capture, real):
            for i in range(5):
                p, b, a, e = synthetic_cycle(i)
                sink.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    written = list(open_log(path).iter_cycles())
    assert [c.seal_digest for c in capture.cycles] == [
        digest(c.payloads["/trace/seal"]) for c in written
    ]
    assert capture.commands == [c.action.command for c in written if c.action]
    assert capture.cycles[3].action == synthetic_cycle(3)[2]


def test_the_minimal_robot_example_runs_and_its_log_explains_itself(tmp_path: Path) -> None:
    out = tmp_path / "robot.mcap"
    subprocess.run(
        [
            sys.executable,
            str(ROOT / "examples" / "minimal_robot.py"),
            "--out",
            str(out),
            "--cycles",
            "40",
        ],
        check=True,
        timeout=60,
    )
    cycles = list(open_log(out).iter_cycles())
    assert len(cycles) == 40
    commands = {c.action.command for c in cycles if c.action}
    assert commands == {"STOP", "SLOW", "CONTINUE"}
