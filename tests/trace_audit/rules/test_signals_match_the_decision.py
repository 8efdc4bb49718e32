"""``read_signals`` reads the layers' JSON directly, for speed; what it reads must be what
the investigator's ``Decision`` view says about the same cycle. The view is the oracle here,
on a simulator run with faults (truncated rationales, dropped sensors, failed checks), the
arm example (actuator channels, no planar motion) and hand-made records that bend the
schema (wrong types, missing optional fields)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path
from typing import Any

import orjson

from sim.runner import RunConfig, run
from trace_audit.causal import Decision, read_decision
from trace_audit.rules.signals import read_signals
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_ACTION, TOPIC_EXECUTION

REPO = Path(__file__).resolve().parents[3]


def _from_decision(decision: Decision, name: str) -> float | None:
    """The signal as the Decision view gives it (docs/rules.md's definitions)."""
    family, _, rest = name.partition(".")
    execution = decision.execution
    if family == "command":
        if decision.command is None:
            return None
        return 1.0 if decision.command.casefold() == rest.casefold() else 0.0
    if family == "factor":
        for f in decision.factors:
            if rest in (f.node, f.name):
                v = f.value
                return float(v) if isinstance(v, int | float) and not isinstance(v, str) else None
        return None
    if execution is None:
        return None
    if family == "check":
        passed = [c.passed for c in execution.checks if c.rule == rest]
        return (1.0 if all(passed) else 0.0) if passed else None
    if family == "flag":
        return 1.0 if rest in execution.problems else 0.0
    channel, _, part = rest.rpartition(".")
    for c in execution.channels:
        if c.name == channel:
            return {"intended": c.intended, "actual": c.actual, "deviation": c.deviation}[part]
    if channel != "speed" or not execution.planar:
        return None
    intended, actual = execution.intended[0], execution.actual[0]
    if part == "deviation":
        return None if intended is None or actual is None else abs(actual - intended)
    value = intended if part == "intended" else actual
    return None if value is None else abs(value)


def _names(cycle: Cycle) -> list[str]:
    """Every signal name this cycle could give, and some it cannot."""
    decision = read_decision(cycle, with_tree=False)
    names = ["command.STOP", "command.stop", "command.CONTINUE", "command.NOPE"]
    names += [f"factor.{f.node}" for f in decision.factors]
    names += [f"factor.{f.name}" for f in decision.factors if f.name]
    names += ["factor.absent", "check.absent", "flag.absent", "channel.absent.actual"]
    execution = decision.execution
    if execution is not None:
        names += [f"check.{c.rule}" for c in execution.checks]
        names += [f"flag.{f}" for f in execution.flags]
        names += [f"channel.{c.name}.{p}" for c in execution.channels for p in _PARTS]
    names += [f"channel.speed.{p}" for p in _PARTS]
    return list(dict.fromkeys(names))


_PARTS = ("intended", "actual", "deviation")


def _assert_same(root: Path) -> int:
    compared = 0
    for cycle in open_log(root).iter_cycles():
        decision = read_decision(cycle, with_tree=False)
        names = _names(cycle)
        command, signals = read_signals(cycle, names)
        assert command == decision.command, cycle.cycle
        for name in names:
            assert signals.get(name) == _from_decision(decision, name), (cycle.cycle, name)
            compared += 1
    return compared


def test_a_simulator_run_with_faults(tmp_path: Path) -> None:
    run(RunConfig(out=tmp_path / "sim", total_cycles=600, seed=3))
    assert _assert_same(tmp_path / "sim") > 600 * 10


def test_the_arm_example(tmp_path: Path) -> None:
    script = REPO / "examples" / "pick_and_place_arm.py"
    subprocess.run([sys.executable, str(script), "--out", str(tmp_path / "arm")], check=True)
    assert _assert_same(tmp_path / "arm") > 100


def _bent(cycle: Cycle, topic: str, layer: Any) -> Cycle:
    payloads = dict(cycle.payloads)
    payloads[topic] = orjson.dumps(layer)
    return dataclasses.replace(cycle, payloads=payloads)


def test_records_that_bend_the_schema(tmp_path: Path) -> None:
    run(RunConfig(out=tmp_path / "sim", total_cycles=5, seed=1))
    cycle = next(iter(open_log(tmp_path / "sim").iter_cycles()))
    actions = [
        {"command": 7, "rationale": {"factors": [{"node": "n", "value": True}]}},
        {"command": "stop", "rationale": {"factors": [{"node": "n", "name": 3, "value": "x"}]}},
        {"command": "SLOW", "rationale": "no"},
    ]
    executions = [
        {"intended": {"angular": 0.2}, "actual": {"linear": -0.4}, "flags": ["a", 3, "b"]},
        {"intended": {}, "checks": [{"rule": "r", "passed": 1}, {"passed": False}, "x"]},
        {"channels": [{"name": "speed", "unit": "m/s", "actual": "fast"}], "flags": "ab"},
        {"channels": [{"unit": "N", "intended": True}], "intended": [1, 2]},
    ]
    for action in actions:
        for execution in executions:
            bent = _bent(_bent(cycle, TOPIC_ACTION, action), TOPIC_EXECUTION, execution)
            decision = read_decision(bent, with_tree=False)
            names = [*_names(bent), "factor.n", "factor.3", "check.r", "check.?", "flag.a"]
            names += ["flag.b", "channel.?.intended", "channel.speed.actual"]
            command, signals = read_signals(bent, names)
            assert command == decision.command
            for name in names:
                assert signals.get(name) == _from_decision(decision, name), (action, name)
