"""The Python twin of examples/cpp_robot/main.cpp: the same cycles, computed the same way
(integer millimetres divided once, C++'s truncating division), logged in process through
``AuditLogger`` so the recorder's log of the C++ robot can be compared with it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trace_runtime import AuditLogger, LoggerConfig

COMMANDS = ("STOP", "SLOW", "CONTINUE")
TARGET_MM_S = (0, 400, 1000)
SOFTWARE = "cpp_robot 1.0"
POLICY = "stop-slow-continue"


def _truncated(a: int, b: int) -> int:
    """C++'s integer division (towards zero), not Python's floor."""
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b > 0) else -q


def period_ns(hz: float) -> int:
    return int(1e9 / hz + 0.5)


def cycle_dicts(i: int, t_ns: int, actual_mm_s: int) -> tuple[dict[str, Any], int]:
    """Cycle ``i`` as the C++ robot sends it (its sensors, then its layers as dicts), and
    the actuator speed it leaves behind."""
    d_mm = 1000 + 100 * abs(i % 90 - 45)
    d = d_mm / 1000.0
    choice = 0 if d_mm < 2000 else 1 if d_mm < 4000 else 2
    target = TARGET_MM_S[choice]
    actual_mm_s += _truncated((target - actual_mm_s) * 6, 10)
    ref = None if i % 10 == 7 else {"topic": "/sensors/range", "log_time_ns": t_ns}
    perception = {
        "entities": [
            {
                "id": "obstacle_1",
                "class": "person",
                "pose": {"position": [d, 0.0, 0.0]},
                "confidence": {"person": 0.9, "pallet": 0.1},
                "evidence": [{"sensor": "range", "weight": 1.0, "ref": ref}],
            }
        ],
        "sensors_used": ["range"],
    }
    belief = _belief(d, d_mm)
    alternatives = [
        {"command": COMMANDS[c], "score": 0.0, "rejected_because": "policy threshold"}
        for c in range(3)
        if c != choice and i % 13 != 5
    ]
    action = {
        "command": COMMANDS[choice],
        "alternatives": alternatives,
        "rationale": {
            "text": f"obstacle at {d_mm} mm",
            "factors": [
                {"node": "obstacle_1.distance", "name": "distance", "value": d, "unit": "m"}
            ],
        },
        "counterfactuals": _counterfactuals(choice),
    }
    execution = {
        "intended": {"linear": target / 1000.0},
        "actual": {"linear": actual_mm_s / 1000.0},
        "deviation": abs(target - actual_mm_s) / 1000.0,
    }
    layers = {"perception": perception, "belief": belief, "action": action}
    return {"t_ns": t_ns, "range_m": d, **layers, "execution": execution}, actual_mm_s


def _belief(d: float, d_mm: int) -> dict[str, Any]:
    return {
        "nodes": [
            {"id": "obstacle_1", "kind": "entity", "p": 0.9, "entity": "obstacle_1"},
            {"id": "obstacle_1.distance", "kind": "state", "p": 0.95, "value": d, "unit": "m"},
            {
                "id": "obstacle_1.risk",
                "kind": "state",
                "p": 0.9,
                "value": min(1000, 1400000 // d_mm) / 1000.0,
            },
        ],
        "edges": [
            {"parent": "obstacle_1", "child": "obstacle_1.distance", "p": 0.95}
            | {"rule": "range_to_distance"},
            {"parent": "obstacle_1.distance", "child": "obstacle_1.risk", "p": 0.9}
            | {"rule": "risk_from_distance"},
        ],
    }


def _counterfactuals(choice: int) -> list[dict[str, Any]]:
    def cf(comparison: str, threshold: float, would: str) -> dict[str, Any]:
        return {
            "factor": "obstacle_1.distance",
            "comparison": comparison,
            "threshold": threshold,
            "would_select": would,
        }

    if choice == 0:
        return [cf(">=", 2.0, "SLOW")]
    if choice == 1:
        return [cf("<", 2.0, "STOP"), cf(">=", 4.0, "CONTINUE")]
    return [cf("<", 4.0, "SLOW")]


def log_in_process(root: Path, robot_id: str, cycles: int, hz: float) -> None:
    """Log the C++ robot's ``--sim-time`` cycles with ``AuditLogger`` in this process."""
    period = period_ns(hz)
    config = LoggerConfig(threaded=False)
    with AuditLogger(
        root,
        robot_id=robot_id,
        period_s=period / 1e9,
        software_version=SOFTWARE,
        policy_version=POLICY,
        clock="sim",
        config=config,
    ) as log:
        actual = 1000
        for i in range(cycles):
            cycle, actual = cycle_dicts(i, i * period, actual)
            with log.cycle(cycle["t_ns"]) as c:
                ref = c.sensor("/sensors/range", {"range_m": cycle["range_m"]})
                evidence = cycle["perception"]["entities"][0]["evidence"][0]
                if evidence["ref"] is not None:
                    evidence["ref"] = ref.model_dump()
                c.perception(cycle["perception"])
                c.belief(cycle["belief"])
                c.action(cycle["action"])
                c.execution(cycle["execution"])
