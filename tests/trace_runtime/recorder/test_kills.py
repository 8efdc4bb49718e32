"""Processes killed for real: the C++ robot with SIGKILL mid-run (at most the cycle in
flight is lost), and the recorder with SIGKILL while the robot runs (the robot keeps its
period, counts what it drops, reconnects to a restarted recorder, which resumes the chain;
verify passes with declared gaps only)."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

from tests.outside import cli
from tests.trace_runtime.recorder.conftest import RecorderProcess, _pairs

HZ = 100


def _verified(root: Path, *notes: str) -> dict[str, Any]:
    """verify's report of a root that passes, with notes of no other kinds than ``notes``."""
    done = cli("verify", root, "--json")
    assert done.returncode == 0, done.stdout + done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    assert report["ok"] and not report["findings"], report["findings"]
    kinds = {note["kind"] for note in report["notes"]}
    assert kinds <= {"signatures_unchecked", *notes}, report["notes"]
    return report


def _robot(binary: Path, socket_path: Path, cycles: int) -> subprocess.Popen[str]:
    command = [str(binary), "--socket", str(socket_path), "--robot-id", "amr-cpp"]
    command += ["--cycles", str(cycles), "--hz", str(HZ), "--sim-time", "--announce"]
    return subprocess.Popen(command, stdout=subprocess.PIPE, text=True)


def test_a_robot_killed_mid_run_loses_at_most_its_cycle_in_flight(
    recorder: RecorderProcess, cpp_robot: Path
) -> None:
    with _robot(cpp_robot, recorder.socket, 100_000) as proc:
        assert proc.stdout is not None
        last = -1
        while last < 30:
            last = int(proc.stdout.readline().split()[1])
        time.sleep(random.uniform(0, 1 / HZ))  # land anywhere inside a cycle
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        for line in proc.stdout.read().splitlines():  # announced before the kill
            last = int(line.split()[1])
    time.sleep(0.5)  # the recorder sees the end of the stream and closes the robot's logger
    code, stderr = recorder.stop()
    assert code == 0, stderr
    report = _verified(recorder.root)
    (robot,) = report["robots"]
    assert robot["cycles_valid"] in (last, last + 1)  # announced cycles 0..last, one may be lost
    assert robot["declared_dropped"] == 0


def test_a_recorder_killed_under_a_running_robot_is_restarted_and_resumes_the_chain(
    recorder: RecorderProcess, cpp_robot: Path
) -> None:
    cycles = 350
    started = time.monotonic()
    with _robot(cpp_robot, recorder.socket, cycles) as proc:
        assert proc.stdout is not None
        while int(proc.stdout.readline().split()[1]) < 80:
            pass
        recorder.kill()
        time.sleep(0.4)  # the robot runs on alone, dropping and counting
        recorder.start()
        out = proc.stdout.read()
        assert proc.wait(timeout=30) == 0
    elapsed = time.monotonic() - started
    code, stderr = recorder.stop()
    assert code == 0, stderr

    last = _pairs(out.strip().splitlines()[-1])
    # The control loop kept its period: it never waited for the recorder.
    assert elapsed < cycles / HZ + 2.0
    assert last["p99_us"] < 2_000
    assert 0 < last["dropped"] < cycles and last["sent"] + last["dropped"] == cycles

    # the killed recorder's segment has no summary: read by a scan, and said so
    report = _verified(recorder.root, "recovered", "declared_gap")
    (robot,) = report["robots"]
    assert robot["segments"] == 2  # the killed recorder's segment, and the resumed one
    assert robot["first_cycle"] == 0
    # What the robot dropped while no recorder listened is declared in the chain; what the
    # killed recorder held unwritten (at most a few cycles) is a gap in time, never a break.
    assert robot["declared_dropped"] == last["dropped"]
    assert robot["cycles_valid"] + robot["declared_dropped"] <= cycles
    assert robot["cycles_valid"] >= last["sent"] - 5
