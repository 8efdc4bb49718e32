"""The C++ robot, run against a real ``trace-recorder``: its log verifies CLEAN, conforms to
the profile, and is the log the same cycles make when a Python robot logs them in process
(the same metrics, and the same bytes in every /trace message)."""

from __future__ import annotations

import json
from pathlib import Path

from tests.outside import cli
from tests.trace_runtime.recorder.conftest import (
    RecorderProcess,
    comparable_metrics,
    run_cpp_robot,
)
from tests.trace_runtime.recorder.warehouse import log_in_process
from trace_runtime import open_log

CYCLES = 180  # two passes of the obstacle: STOP, SLOW and CONTINUE all taken
HZ = 200.0


def test_the_cpp_robot_log_verifies_conforms_and_equals_the_in_process_log(
    recorder: RecorderProcess, cpp_robot: Path, tmp_path: Path
) -> None:
    last, _ = run_cpp_robot(cpp_robot, recorder.socket, "amr-cpp", CYCLES, HZ, "--sim-time")
    code, stderr = recorder.stop()
    assert code == 0, stderr
    assert last["sent"] == CYCLES and last["dropped"] == 0

    verified = cli("verify", recorder.root, "--json")
    assert verified.returncode == 0, verified.stdout + verified.stderr
    report = json.loads(verified.stdout)
    assert report["ok"] and not report["findings"]
    assert report["cycles_valid"] == CYCLES
    doctor = cli("doctor", recorder.root, "--json")
    assert doctor.returncode == 0 and json.loads(doctor.stdout)["conforms"], doctor.stdout

    twin = tmp_path / "twin"
    log_in_process(twin, "amr-cpp", CYCLES, HZ)
    remote = comparable_metrics(recorder.root)
    assert remote == comparable_metrics(twin)
    # The policy's faults are there to be found: not every decision is traceable or
    # reconstructable, so equal metrics are not two ones.
    assert 0 < remote["overall"]["et"]["mean"] < 1
    assert 0 < remote["overall"]["dr"] < 1

    def payloads(root: Path) -> list[dict[str, bytes]]:
        return [c.payloads for c in open_log(root).iter_cycles()]

    assert payloads(recorder.root) == payloads(twin)


def test_the_recorder_keeps_a_robot_s_chain_across_clients(
    recorder: RecorderProcess, cpp_robot: Path
) -> None:
    """A robot that connects again continues its chain in a new segment."""
    for _ in range(2):
        run_cpp_robot(cpp_robot, recorder.socket, "amr-cpp", 20, HZ)
    code, stderr = recorder.stop()
    assert code == 0, stderr
    verified = json.loads(cli("verify", recorder.root, "--json").stdout)
    assert verified["ok"] and verified["cycles_valid"] == 40
    assert [s["number"] for s in verified["segments"]] == [0, 1]
