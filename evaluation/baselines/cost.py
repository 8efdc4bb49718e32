"""TRACE's own cost: time per decision cycle with audit logging on and off.

Two measurements, both as medians over repeats run back to back (on, off, on, off, ...) so
that load from other processes hits both alike:

- ``measure_overhead``: the simulator's full loop (world, sensors, the four layers, the
  logger as the paper's runs use it: synchronous, one cycle per write) over the paper's
  scenario runs, once with ``AuditLogger`` and once with ``NullLogger``, same seeds. Faults
  are off so both runs make exactly the same cycles (an injected write timeout would make
  the logged run forget a cycle the unlogged one keeps); the commands are compared.
- ``measure_scaling``: a synthetic decision loop whose records hold ``n`` perceived
  entities and ``k`` candidate actions, to see how the logging cost grows with them (the
  paper's complexity table); the simulator's own scenes never go past a handful of
  entities and its policy has four commands.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sim.faults import FaultRates
from sim.nulllog import NullLogger
from sim.runner import RunConfig, run
from trace_runtime import AuditLogger, LoggerConfig

__all__ = [
    "Overhead",
    "ScalingPoint",
    "measure_overhead",
    "measure_scaling",
    "synthetic_cycle",
]

PERIOD_NS = 100_000_000


@dataclass(frozen=True, slots=True)
class Overhead:
    """Wall-clock and CPU time per cycle (us), medians over runs.

    CPU time (``time.process_time``: this process, user + system) is what the loop itself
    spent; wall time also holds whatever other processes took from it on a shared machine.
    """

    on_us: float
    off_us: float
    on_cpu_us: float
    off_cpu_us: float
    cycles: int
    """Cycles per run."""
    runs: int
    """Runs per side (seeds x repeats)."""
    same_commands: bool
    """Both sides made the same command every cycle (so they did the same work)."""
    per_seed: dict[int, tuple[float, float]]
    """Seed -> (median on, median off) CPU us per cycle over that seed's repeats."""

    @property
    def overhead_us(self) -> float:
        return self.on_us - self.off_us

    @property
    def overhead_cpu_us(self) -> float:
        return self.on_cpu_us - self.off_cpu_us


@dataclass(frozen=True, slots=True)
class ScalingPoint:
    """Per-cycle wall-clock and CPU time (us) with logging on and off at one (n, k)."""

    entities: int
    actions: int
    on_us: float
    off_us: float
    on_cpu_us: float
    off_cpu_us: float
    bytes_per_cycle: int

    @property
    def overhead_us(self) -> float:
        return self.on_us - self.off_us

    @property
    def overhead_cpu_us(self) -> float:
        return self.on_cpu_us - self.off_cpu_us


def measure_overhead(
    seeds: Sequence[int], cycles: int, workdir: Path, repeats: int = 1
) -> Overhead:
    """Median time per cycle of the scenario runs with logging on and off (same seeds)."""
    on: list[float] = []
    off: list[float] = []
    cpu: dict[bool, list[float]] = {True: [], False: []}
    per_seed: dict[int, tuple[float, float]] = {}
    same = True
    for seed in seeds:
        first = len(cpu[True])
        for r in range(repeats):
            results = {}
            for audit in (True, False):
                config = RunConfig(
                    out=workdir / f"overhead-{seed}-{r}-{'on' if audit else 'off'}.mcap",
                    cycles=cycles,
                    seed=seed,
                    faults=FaultRates.off(),
                    audit=audit,
                )
                cpu_started = time.process_time()
                result = run(config)
                cpu[audit].append((time.process_time() - cpu_started) / result.cycles * 1e6)
                (on if audit else off).append(result.elapsed_s / result.cycles * 1e6)
                results[audit] = result.commands
            same = same and results[True] == results[False]
        per_seed[seed] = (
            statistics.median(cpu[True][first:]),
            statistics.median(cpu[False][first:]),
        )
    return Overhead(
        on_us=statistics.median(on),
        off_us=statistics.median(off),
        on_cpu_us=statistics.median(cpu[True]),
        off_cpu_us=statistics.median(cpu[False]),
        cycles=cycles * 5,
        runs=len(on),
        same_commands=same,
        per_seed=per_seed,
    )


def log_synthetic_cycle(c: Any, records: dict[str, Any]) -> None:
    """Hand a ``synthetic_cycle`` to a cycle builder as a robot would: the scan first, its
    ref into every entity's evidence, then the four layers."""
    ref = c.sensor("/sensors/lidar", records["scan"])
    for entity in records["perception"]["entities"]:
        entity["evidence"][0]["ref"] = ref
    c.perception(records["perception"])
    c.belief(records["belief"])
    c.action(records["action"])
    c.execution(records["execution"])


def synthetic_cycle(n: int, k: int, cycle: int) -> dict[str, Any]:
    """Records of one decision with ``n`` entities and ``k`` candidate actions (plain dicts),
    shaped like the simulator's; ``ref`` is filled in by the caller."""
    entities = []
    nodes: list[dict[str, Any]] = []
    edges: list[dict[str, Any]] = []
    for i in range(n):
        eid = f"ped_{i}"
        d = 1.0 + 0.3 * i + 0.01 * (cycle % 7)
        entities.append(_synthetic_entity(eid, i, d))
        nodes += [
            {"id": eid, "kind": "entity", "label": "person", "p": 0.97, "value": "person",
             "entity": eid},
            {"id": f"{eid}.distance", "kind": "state", "label": "distance", "p": 0.97,
             "value": round(d, 3), "unit": "m"},
            {"id": f"{eid}.collision_risk", "kind": "state", "label": "collision risk",
             "p": 0.9, "value": round(1.0 / d, 3)},
        ]  # fmt: skip
        edges += [
            {"parent": eid, "child": f"{eid}.distance", "p": 0.97, "rule": "range"},
            {"parent": f"{eid}.distance", "child": f"{eid}.collision_risk", "p": 0.9,
             "rule": "risk = proximity"},
        ]  # fmt: skip
    factors = [f"ped_{i}.collision_risk" for i in range(n)]
    action = _synthetic_action(factors, [f"A{j}" for j in range(k)])
    execution = {
        "intended": {"linear": 0.5, "angular": 0.0},
        "actual": {"linear": 0.49, "angular": 0.0},
        "deviation": 0.01,
        "checks": [{"rule": "max_speed", "passed": True, "value": 0.49, "limit": 1.5}],
        "flags": [],
    }
    return {
        "scan": {"ranges": [round(1.0 + 0.01 * b, 2) for b in range(10 * n)]},
        "perception": {"entities": entities, "sensors_used": ["lidar"]},
        "belief": {"nodes": nodes, "edges": edges},
        "action": action,
        "execution": execution,
    }


def _synthetic_entity(eid: str, i: int, d: float) -> dict[str, Any]:
    """Pedestrian ``i`` at distance ``d``, with one LiDAR evidence item."""
    return {
        "id": eid,
        "class": "person",
        "pose": {
            "position": [d, 0.5 * i, 0.0],
            "orientation": [0.0, 0.0, 0.0, 1.0],
            "frame": "map",
        },
        "velocity": [0.0, 0.5, 0.0],
        "confidence": {"person": 0.97, "forklift": 0.01, "pallet": 0.02},
        "evidence": [
            {
                "sensor": "lidar",
                "weight": 1.0,
                "region": {"kind": "beams", "values": [i, i + 5], "frame": "lidar"},
                "ref": None,
            }
        ],
    }


def _synthetic_action(factors: list[str], commands: list[str]) -> dict[str, Any]:
    """The first of ``commands`` chosen over the others, with a what-if per factor each."""
    return {
        "command": commands[0],
        "parameters": {"linear": 0.5, "angular": 0.0},
        "score": 1.0,
        "alternatives": [
            {"command": c, "score": -0.1 * j, "rejected_because": f"{factors[0]} too high"}
            for j, c in enumerate(commands[1:], 1)
        ],
        "rationale": {
            "text": "synthetic",
            "factors": [{"node": f, "name": "collision_risk", "value": 0.5} for f in factors],
            "truncated": False,
        },
        # one what-if per (factor, alternative) pair: the O(n k) part of the record
        "counterfactuals": [
            {"factor": f, "comparison": ">=", "threshold": 0.2, "would_select": c}
            for f in factors
            for c in commands[1:]
        ],
        "counterfactuals_none_applicable": False,
    }


WARM_UP_CYCLES = 5
"""Cycles logged before timing starts: the first write opens the segment (a one-off)."""


def _loop(logger: AuditLogger | NullLogger, n: int, k: int, cycles: int) -> tuple[float, float]:
    """(wall, CPU) seconds per cycle of: build the records, hand them to ``logger`` (open and
    close of the log not counted: they happen once per session, not per cycle)."""
    started = cpu_started = 0.0
    for i in range(WARM_UP_CYCLES + cycles):
        if i == WARM_UP_CYCLES:
            started, cpu_started = time.perf_counter(), time.process_time()
        with logger.cycle(i * PERIOD_NS) as c:
            log_synthetic_cycle(c, synthetic_cycle(n, k, i))
    elapsed, cpu = time.perf_counter() - started, time.process_time() - cpu_started
    logger.close()
    return elapsed / cycles, cpu / cycles


def measure_scaling(
    entities: Sequence[int],
    actions: Sequence[int],
    cycles: int,
    repeats: int = 3,
    progress: Callable[[], None] | None = None,
) -> list[ScalingPoint]:
    """Per-cycle time on and off for every (n, k); medians of ``repeats`` back-to-back runs."""
    points = []
    with tempfile.TemporaryDirectory(prefix="trace-scaling-") as tmp:
        for n in entities:
            for k in actions:
                on: list[tuple[float, float]] = []
                off: list[tuple[float, float]] = []
                size = 0
                for r in range(repeats):
                    path = Path(tmp) / f"n{n}-k{k}-{r}.mcap"
                    logger = AuditLogger(
                        path,
                        robot_id="scaling",
                        period_s=0.1,
                        clock="sim",
                        config=LoggerConfig(threaded=False, fsync_interval_s=None),
                    )
                    on.append(_loop(logger, n, k, cycles))
                    size = logger.stats.bytes_written // (cycles + WARM_UP_CYCLES)
                    off.append(_loop(NullLogger(), n, k, cycles))
                    path.unlink()
                points.append(
                    ScalingPoint(
                        n,
                        k,
                        on_us=statistics.median(w for w, _ in on) * 1e6,
                        off_us=statistics.median(w for w, _ in off) * 1e6,
                        on_cpu_us=statistics.median(c for _, c in on) * 1e6,
                        off_cpu_us=statistics.median(c for _, c in off) * 1e6,
                        bytes_per_cycle=size,
                    )
                )
                if progress is not None:
                    progress()
    return points
