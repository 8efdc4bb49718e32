"""Batched writes in long runs, and the decision cache: what changes and what must not."""

from __future__ import annotations

import hashlib
import itertools
import math
from pathlib import Path
from typing import Any

import orjson
import pytest
from typer.testing import CliRunner

from sim import FaultRates, RunConfig, RunResult, read_truth, run
from sim import decision as decision_module
from sim.belief import build_belief
from sim.cli import app
from sim.decision import Decider
from sim.perception import CorridorView, PerceptionOutput
from trace_runtime import open_log

# Every fault of the paper except the audit-write timeout.
NO_TIMEOUTS = FaultRates(audit_write_timeout=0.0)


def _seals(result: RunResult) -> list[tuple[int, str]]:
    return [
        (c.cycle, hashlib.sha256(c.payloads["/trace/seal"]).hexdigest())
        for c in open_log(result.out).iter_cycles()
    ]


def test_batched_writes_change_only_how_cycles_are_chunked(tmp_path: Path) -> None:
    one = run(RunConfig(out=tmp_path / "one.mcap", total_cycles=600, seed=8, faults=NO_TIMEOUTS))
    batched = run(
        RunConfig(
            out=tmp_path / "fifty.mcap",
            total_cycles=600,
            seed=8,
            faults=NO_TIMEOUTS,
            batch_cycles=50,
        )
    )
    assert batched.batch_cycles == 50 and batched.dropped == 0
    assert _seals(batched) == _seals(one)
    assert one.truth.read_bytes() == batched.truth.read_bytes()
    assert batched.bytes_written < one.bytes_written / 2  # 50 cycles a chunk compress better


def test_a_timed_out_batch_write_loses_that_whole_batch_and_nothing_else(tmp_path: Path) -> None:
    n, size, p = 1200, 20, 0.25
    rates = FaultRates.off()
    rates = FaultRates(**{**rates.as_dict(), "audit_write_timeout": p, "camera_unavailable": 0.1})
    result = run(
        RunConfig(out=tmp_path / "t.mcap", total_cycles=n, seed=4, faults=rates, batch_cycles=size)
    )
    cycles = {c.cycle: c for c in open_log(result.out).iter_cycles()}
    lost = sorted(set(range(n)) - set(cycles))
    truth = read_truth(result.truth)
    timeouts = [t for t in truth if t["kind"] == "audit_write_timeout"]
    assert [t["cycle"] for t in timeouts] == lost
    # Losses come in whole writes: cycles [k * size, (k + 1) * size), each listed with its batch.
    batches = {k // size for k in lost}
    assert lost == [k for b in sorted(batches) for k in range(b * size, (b + 1) * size)]
    for t in timeouts:
        first = t["cycle"] // size * size
        assert t["detail"] == {"dropped": True, "batch": [first, first + size - 1]}
    # The timeout strikes writes (here n / size of them) at its rate.
    writes = n // size
    assert abs(len(batches) - writes * p) <= 4.5 * math.sqrt(writes * p * (1 - p)) + 1
    assert result.dropped == len(lost) > 0
    # Every gap is declared by the next seal written after it.
    written = sorted(cycles)
    for prev, nxt in itertools.pairwise(written):
        seal = cycles[nxt].seal
        assert seal is not None and seal.dropped == nxt - prev - 1
    # No written cycle points at a sensor reading of a lost batch: the evidence was forgotten.
    logged = {(m.topic, m.log_time_ns) for c in cycles.values() for m in c.sensors}
    for c in cycles.values():
        assert c.perception is not None
        for entity in c.perception.entities:
            for ev in entity.evidence:
                assert ev.ref is not None and (ev.ref.topic, ev.ref.log_time_ns) in logged


def test_the_decision_cache_changes_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cached = run(RunConfig(out=tmp_path / "cached.mcap", scenario="all", cycles=80, seed=6))
    monkeypatch.setattr(decision_module, "CACHE_SIZE", 0)
    fresh = run(RunConfig(out=tmp_path / "fresh.mcap", scenario="all", cycles=80, seed=6))
    assert _seals(cached) == _seals(fresh)
    assert cached.truth.read_bytes() == fresh.truth.read_bytes()


def _empty_aisle() -> Any:
    corridor = CorridorView(clearance=10.0, length=10.0, blocker=None, evidence=())
    return build_belief(PerceptionOutput((), corridor, ("lidar",), ()), (5.0, 7.0, 0.0), 1.2)


def test_the_same_policy_input_is_decided_once() -> None:
    decider = Decider()
    first = decider.decide(_empty_aisle())[2]
    again = decider.decide(_empty_aisle())[2]
    assert again is first and (decider.hits, decider.misses) == (1, 1)
    assert first.outcome.command == "CONTINUE" and first.counterfactuals


def test_cli_duration_runs_batch_by_default_and_scenario_runs_refuse_batch(
    tmp_path: Path,
) -> None:
    runner = CliRunner()
    res = runner.invoke(
        app, ["run", "--duration", "30s", "--out", str(tmp_path / "d.mcap"), "--json"]
    )
    assert res.exit_code == 0, res.output
    summary: dict[str, Any] = orjson.loads(res.stdout)
    assert summary["cycles"] == 300 and summary["batch_cycles"] == 50
    res = runner.invoke(
        app,
        ["run", "--duration", "10s", "--batch", "1", "--out", str(tmp_path / "e.mcap"), "--json"],
    )
    assert res.exit_code == 0 and orjson.loads(res.stdout)["batch_cycles"] == 1
    res = runner.invoke(app, ["run", "--batch", "10", "--out", str(tmp_path / "f.mcap")])
    assert res.exit_code == 2
    assert res.stderr.startswith("trace-sim: --batch needs --duration")
    res = runner.invoke(
        app, ["run", "--duration", "10s", "--batch", "0", "--out", str(tmp_path / "g.mcap")]
    )
    assert res.exit_code == 2 and res.stderr.count("\n") == 1


def test_a_second_run_into_a_log_root_keeps_the_first_runs_truth(tmp_path: Path) -> None:
    """The second run continues the robot's chain in the root (a restart): the ground truth
    of the faults injected in the first run stays in the sidecar beside the second's."""
    root = tmp_path / "root"
    first = run(RunConfig(out=root, total_cycles=300, seed=1))
    first_truth = read_truth(first.truth)
    assert first_truth
    second = run(RunConfig(out=root, total_cycles=300, seed=2))
    both = read_truth(second.truth)
    assert second.truth == first.truth
    assert both[: len(first_truth)] == first_truth and len(both) > len(first_truth)
    assert min(t["cycle"] for t in both[len(first_truth) :]) >= 300
