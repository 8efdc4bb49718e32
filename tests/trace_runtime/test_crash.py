"""A robot killed with SIGKILL leaves a log whose complete cycles are all recovered."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from trace_runtime import open_log
from trace_runtime.chain import digest
from trace_runtime.records import GENESIS, TOPIC_SEAL

ROBOT = Path(__file__).resolve().parents[2] / "examples" / "minimal_robot.py"


def _run_and_kill(out: Path, after_cycles: int) -> int:
    """Start the example robot at 100 Hz, SIGKILL it; return the last cycle it committed."""
    command = [
        sys.executable,
        str(ROBOT),
        "--out",
        str(out),
        "--cycles",
        "100000",
        "--period",
        "0.01",
        "--announce",
    ]
    with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as proc:
        assert proc.stdout is not None
        last = -1
        deadline = time.monotonic() + 30
        while last < after_cycles and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            last = int(line)
        time.sleep(random.uniform(0, 0.01))  # land anywhere inside a cycle
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        # Cycles committed between our last read and the kill were announced too.
        for line in proc.stdout.read().splitlines():
            last = int(line)
    return last


@pytest.mark.parametrize("after_cycles", [5, 40])
def test_sigkill_loses_at_most_the_cycle_in_flight(tmp_path: Path, after_cycles: int) -> None:
    out = tmp_path / "crashed.mcap"
    last_committed = _run_and_kill(out, after_cycles)
    log = open_log(out)
    assert log.recovered  # no summary: the reader fell back to a scan
    cycles = list(log.iter_cycles())
    numbers = [c.cycle for c in cycles]
    assert numbers == list(range(len(numbers))), "recovered cycles are contiguous from 0"
    assert numbers[-1] >= last_committed - 1, (numbers[-1], last_committed)
    prev = GENESIS
    for cycle in cycles:
        seal = cycle.seal
        assert seal is not None and seal.prev == prev and seal.digests == cycle.digests()
        prev = digest(cycle.payloads[TOPIC_SEAL])


def test_a_cut_inside_the_last_chunk_keeps_every_earlier_cycle(tmp_path: Path, log_writer) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "cut.mcap"
    log_writer(path, 20)
    data = path.read_bytes()
    first_chunk = data.index(b"zstd") - 40  # inside the first chunk record's header
    for cut in (len(data) - 200, len(data) // 2, first_chunk):
        part = tmp_path / f"part-{cut}.mcap"
        part.write_bytes(data[:cut])
        log = open_log(part)
        numbers = [c.cycle for c in log.iter_cycles()]
        assert numbers == list(range(len(numbers)))
        assert log.recovered
    assert len(list(open_log(tmp_path / f"part-{len(data) - 200}.mcap").iter_cycles())) == 20
