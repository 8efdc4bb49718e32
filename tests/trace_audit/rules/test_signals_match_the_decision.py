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
from trace_audit.sensor_health import sensor_health
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_ACTION, TOPIC_EXECUTION, TOPIC_PERCEPTION

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


def _from_health(cycle: Cycle, name: str) -> float | None:
    """A ``perception.*`` or ``evidence.*`` signal as explain's sensor health gives it, from
    the full parse of the layers."""
    perception = cycle.layer(TOPIC_PERCEPTION)
    if not isinstance(perception, dict) and name.startswith("perception."):
        return None
    health = sensor_health(perception, cycle.layer(TOPIC_EXECUTION), cycle.t_ns, 0)
    family, _, rest = name.partition(".")
    key, _, which = rest.partition(".")
    if family == "perception":
        listed = health.unavailable if key == "sensors_unavailable" else health.used
        return (1.0 if which in listed else 0.0) if which else float(len(listed))
    ages = [c.age_ns for c in health.cited if not which or c.sensor == which]
    return max(ages) / 1e9 if ages else None


def _oracle(cycle: Cycle, decision: Decision, name: str) -> float | None:
    if name.partition(".")[0] in ("perception", "evidence"):
        return _from_health(cycle, name)
    return _from_decision(decision, name)


def _health_names(cycle: Cycle) -> list[str]:
    perception = cycle.layer(TOPIC_PERCEPTION)
    health = sensor_health(perception, cycle.layer(TOPIC_EXECUTION), cycle.t_ns, 0)
    names = ["perception.sensors_used", "perception.sensors_unavailable", "evidence.age_s"]
    for key, listed in (("sensors_used", health.used), ("sensors_unavailable", health.unavailable)):
        names += [f"perception.{key}.{n}" for n in listed]
    names += [f"evidence.age_s.{c.sensor}" for c in health.cited]
    return [*names, "perception.sensors_unavailable.absent", "evidence.age_s.absent"]


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
    names += _health_names(cycle)
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
            assert signals.get(name) == _oracle(cycle, decision, name), (cycle.cycle, name)
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
                assert signals.get(name) == _oracle(bent, decision, name), (action, name)


def test_perception_records_that_bend_the_schema(tmp_path: Path) -> None:
    """Sensor lists and refs of the wrong types read as explain's sensor health reads them."""
    run(RunConfig(out=tmp_path / "sim", total_cycles=5, seed=1))
    cycle = next(iter(open_log(tmp_path / "sim").iter_cycles()))
    ref = {"topic": "/s", "log_time_ns": cycle.t_ns - 5}
    perceptions = [
        {"sensors_used": ["a", 3, "a"], "sensors_unavailable": "cam"},
        {"sensors_unavailable": ["cam"], "entities": [{"id": "e", "evidence": [{"ref": ref}]}]},
        {"entities": [{"evidence": [{"sensor": 5, "ref": {"log_time_ns": 1.5}}, "x"]}]},
        {"entities": [{"id": "e", "evidence": [{"sensor": "lidar", "ref": ref}]}]},
        [],
    ]
    executions = [
        {"channels": [{"name": "elbow", "ref": dict(ref, log_time_ns=cycle.t_ns + 7)}]},
        {"channels": [{"name": 3, "ref": "no"}]},
    ]
    for perception in perceptions:
        for execution in executions:
            bent = _bent(_bent(cycle, TOPIC_PERCEPTION, perception), TOPIC_EXECUTION, execution)
            names = [*_health_names(bent), "perception.sensors_used.a", "evidence.age_s.lidar"]
            names += ["evidence.age_s.elbow", "evidence.age_s.?"]
            _command, signals = read_signals(bent, names)
            for name in names:
                assert signals.get(name) == _from_health(bent, name), (perception, name)
