"""trace-sim: the reference robot, a warehouse simulator that logs through ``trace_runtime``.

``run(RunConfig(out=...))`` simulates the paper's five scenarios through the four TRACE
layers and writes a TRACE log plus a ground-truth sidecar of the faults it injected.
"""

from __future__ import annotations

from sim.faults import FaultRates, read_truth, truth_path_for
from sim.runner import (
    CYCLES_PER_DAY,
    RunConfig,
    RunResult,
    SimError,
    SimOutputError,
    SimUsageError,
    parse_duration,
    run,
)
from sim.scenarios import EPISODE_CYCLES, SCENARIOS, Scenario

__all__ = [
    "CYCLES_PER_DAY",
    "EPISODE_CYCLES",
    "SCENARIOS",
    "FaultRates",
    "RunConfig",
    "RunResult",
    "Scenario",
    "SimError",
    "SimOutputError",
    "SimUsageError",
    "parse_duration",
    "read_truth",
    "run",
    "truth_path_for",
]
