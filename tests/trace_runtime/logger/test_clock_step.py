"""A robot's clock that steps back (chrony, a ROS time source reset) seen from outside: a real
``AuditLogger`` is given a time that goes back, and ``trace-audit`` in another process reads
the log. The control loop gets no exception, every cycle keeps its number in one hash chain,
and verify, info and metrics show a declared clock step: a note, not tampering nor a gap."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from tests.trace_runtime.hostile import run_cli
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000
START_NS = 1_777_000_000_000_000_000  # a wall clock, as chrony keeps it
STEPS = {25: 1_250_000_000, 33: 1}
"""Cycle number -> how far the clock went back just before it (the second, 1 ns, is the
smallest step there is)."""


def _robot(root: Path, config: LoggerConfig) -> AuditLogger:
    """40 cycles at 10 Hz on a clock that steps back before cycles 25 and 33."""
    t_ns = START_NS
    with AuditLogger(root, robot_id="amr-1", config=config) as log:
        for i in range(40):
            if i:
                t_ns += PERIOD_NS - STEPS.get(i, 0) - (PERIOD_NS if i in STEPS else 0)
            assert log.log_cycle(t_ns, action=synthetic_cycle(i)[2]) == i
    return log


def _json(*args: str) -> Any:
    done = run_cli([*args, "--json"])
    assert done.code == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.parametrize(
    ("threaded", "batch_cycles"),
    [(True, 64), (False, 1), (False, 7)],
    ids=["writer-thread", "one-per-batch", "step-inside-a-batch"],
)
def test_a_clock_step_back_is_declared_and_read_as_one_chain(
    tmp_path: Path, threaded: bool, batch_cycles: int
) -> None:
    root = tmp_path / "root"
    config = LoggerConfig(threaded=threaded, batch_cycles=batch_cycles, fsync_interval_s=None)
    log = _robot(root, config)
    assert (log.stats.clock_steps, log.stats.written, log.stats.dropped) == (2, 40, 0)

    verified = _json("verify", str(root))
    assert verified["findings"] == []
    steps = [n for n in verified["notes"] if n["kind"] == "clock_step"]
    assert [n["first_cycle"] for n in steps] == [25, 33]
    assert "stepped back 1.250 s before cycle 25" in steps[0]["message"]
    assert "2026-04-24T" in steps[0]["message"]  # a wall clock is shown as one
    assert verified["cycles_valid"] == verified["cycles"] == 40

    info = _json("info", str(root))
    declared = [
        (s["first_cycle"], s["from_ns"] - s["to_ns"], s["declared"]) for s in info["clock_steps"]
    ]
    assert declared == [(25, 1_250_000_000, True), (33, 1, True)]
    assert info["cycles"] == 40 and info["gaps"] == []

    overall = _json("metrics", str(root))["overall"]
    assert overall["gaps"] == 0 and overall["tc"] == 1.0
    assert overall["clock_restarts"] == 2

    people = run_cli(["info", str(root), "--plain"])
    assert people.code == 0 and "stepped back 1.250 s before cycle 25" in people.stdout


def test_a_restart_on_a_lower_clock_is_not_declared_a_step(tmp_path: Path) -> None:
    """Two processes: the second starts its monotonic clock lower. The writer of the second
    did not see the first's time, so the boundary is a restart, not a declared step."""
    root = tmp_path / "root"
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    for start in (50 * PERIOD_NS, 10 * PERIOD_NS):
        with AuditLogger(root, robot_id="r", clock="monotonic", config=config) as log:
            for i in range(5):
                log.log_cycle(start + i * PERIOD_NS, action=synthetic_cycle(i)[2])
    info = _json("info", str(root))
    (step,) = info["clock_steps"]
    assert (step["first_cycle"], step["declared"]) == (5, False)
    kinds = [n["kind"] for n in _json("verify", str(root))["notes"]]
    assert "clock_restart" in kinds and "clock_step" not in kinds
