"""Fixtures that build small TRACE logs in tmp_path with the real ``AuditLogger``.

The logs follow the shape of the paper's warehouse example: a LiDAR scan is the evidence for
a perceived entity, the belief graph derives a distance and a collision risk from it, and the
policy picks STOP / SLOW / REROUTE / CONTINUE with alternatives, counterfactuals and a
counterfactual decision tree. ``Script`` says which situation each stretch of cycles is in
and which links to break, so tests can check that a broken link is reported, not hidden.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from mcap.writer import Writer

from trace_runtime import (
    AuditLogger,
    CycleBuilder,
    EvidenceRef,
    LoggerConfig,
    RawMessage,
    open_segment,
)
from trace_runtime.session import SESSION_METADATA
from trace_runtime.testing import simulate_crash

T0_NS = 100_000_000_000  # the fixture logs start at t = 100 s (not 0: relative times matter)
PERIOD_NS = 100_000_000

# situation -> (command, distance to the nearest pedestrian or None, collision risk)
SITUATIONS: dict[str, tuple[str, float | None, float]] = {
    "clear": ("CONTINUE", None, 0.05),
    "ped_far": ("SLOW", 3.2, 0.35),
    "ped_close": ("STOP", 1.5, 0.70),
    "blocked": ("REROUTE", None, 0.10),
}

# Faults a stretch of cycles can carry (each breaks one documented link on purpose).
FAULTS = frozenset({"null_ref", "no_edge", "truncated", "no_cf", "no_evidence", "flag", "old_ref"})


@dataclass(frozen=True)
class Stretch:
    situation: str
    cycles: int
    faults: frozenset[str] = field(default_factory=frozenset)


def stretch(situation: str, cycles: int, *faults: str) -> Stretch:
    unknown = set(faults) - FAULTS
    assert not unknown, unknown
    return Stretch(situation, cycles, frozenset(faults))


DEFAULT_SCRIPT = (
    stretch("clear", 30),
    stretch("ped_far", 10),
    stretch("ped_close", 20),
    stretch("clear", 10),
    stretch("blocked", 10),
    stretch("ped_close", 5, "null_ref"),
    stretch("clear", 15),
)


def fill_cycle(
    c: CycleBuilder,
    situation: str,
    faults: frozenset[str] = frozenset(),
    previous: EvidenceRef | None = None,
) -> EvidenceRef:
    """Add the four layers of one cycle in ``situation`` to ``c``; return its lidar ref.

    With the ``old_ref`` fault the evidence points at ``previous`` (an earlier cycle's
    reading) instead of this cycle's.
    """
    command, distance, risk = SITUATIONS[situation]
    scan: dict[str, Any] = {"angle_min": -1.57, "angle_increment": 0.0175, "ranges": [4.0] * 24}
    if distance is not None:
        scan["ranges"][10:14] = [distance] * 4
    own = c.sensor("/sensors/lidar", scan)
    ref = previous if "old_ref" in faults and previous is not None else own
    entities: list[dict[str, Any]] = []
    nodes: list[dict[str, Any]] = []
    edges: list[dict[str, Any]] = []
    factors: list[dict[str, Any]] = []
    if distance is not None:
        evidence = (
            []
            if "no_evidence" in faults
            else [
                {
                    "sensor": "lidar",
                    "weight": 0.8,
                    "region": {"kind": "beams", "values": [10, 13]},
                    "ref": None if "null_ref" in faults else ref.model_dump(),
                }
            ]
        )
        entities.append(
            {
                "id": "ped_1",
                "class": "person",
                "pose": {"position": [distance, 0.0, 0.0]},
                "confidence": {"person": 0.92, "forklift": 0.03, "shelf": 0.05},
                "evidence": evidence,
            }
        )
        nodes += [
            {"id": "ped_1", "kind": "entity", "label": "person", "p": 0.92, "entity": "ped_1"},
            {
                "id": "ped_1.distance",
                "kind": "state",
                "label": "distance to pedestrian",
                "p": 0.95,
                "value": distance,
                "unit": "m",
            },
        ]
        edges.append(
            {"parent": "ped_1", "child": "ped_1.distance", "p": 0.95, "rule": "range_from_cluster"}
        )
        if "no_edge" not in faults:
            edges.append(
                {
                    "parent": "ped_1.distance",
                    "child": "collision_risk",
                    "p": 0.9,
                    "rule": "ttc_risk",
                }
            )
        factors.append(
            {"node": "ped_1.distance", "name": "distance", "value": distance, "unit": "m"}
        )
    nodes.append(
        {
            "id": "collision_risk",
            "kind": "state",
            "label": "collision risk",
            "p": risk,
            "value": risk,
        }
    )
    if distance is None:
        # No pedestrian: the risk comes from the free lane the scan shows ahead.
        entities.append(
            {
                "id": "lane",
                "class": "free_space",
                "pose": {"position": [3.0, 0.0, 0.0]},
                "confidence": {"free_space": 0.97},
                "evidence": [
                    {
                        "sensor": "lidar",
                        "weight": 1.0,
                        "region": {"kind": "beams", "values": [0, 23]},
                        "ref": None if "null_ref" in faults else ref.model_dump(),
                    }
                ],
            }
        )
        nodes.append(
            {"id": "lane", "kind": "entity", "label": "free lane", "p": 0.97, "entity": "lane"}
        )
        if "no_edge" not in faults:
            edges.append(
                {"parent": "lane", "child": "collision_risk", "p": 0.97, "rule": "clearance_risk"}
            )
    factors.append({"node": "collision_risk", "name": "collision_risk", "value": risk})
    if situation == "blocked":
        entities.append(
            {
                "id": "pallet_7",
                "class": "pallet",
                "pose": {"position": [2.0, 0.0, 0.0]},
                "confidence": {"pallet": 0.88, "person": 0.02},
                "evidence": [{"sensor": "lidar", "weight": 0.9, "ref": ref.model_dump()}],
            }
        )
        nodes += [
            {
                "id": "pallet_7",
                "kind": "entity",
                "label": "pallet",
                "p": 0.88,
                "entity": "pallet_7",
            },
            {
                "id": "aisle_blocked",
                "kind": "state",
                "label": "aisle blocked",
                "p": 0.85,
                "value": True,
            },
        ]
        edges.append(
            {"parent": "pallet_7", "child": "aisle_blocked", "p": 0.85, "rule": "occupancy_in_lane"}
        )
        factors.insert(0, {"node": "aisle_blocked", "name": "aisle_blocked", "value": True})
    c.perception({"entities": entities, "sensors_used": ["lidar"]})
    c.belief({"nodes": nodes, "edges": edges})
    c.action(_action(command, distance, risk, faults))
    flags = [f"scenario:{situation}"] + (["deviation_high"] if "flag" in faults else [])
    c.execution(
        {
            "intended": {"linear": _speed(command)},
            "actual": {"linear": _speed(command) + (0.3 if "flag" in faults else 0.01)},
            "deviation": 0.3 if "flag" in faults else 0.01,
            "checks": [
                {"rule": "min_clearance", "passed": True, "value": distance or 4.0, "limit": 0.5}
            ],
            "flags": flags,
        }
    )
    return own


def _speed(command: str) -> float:
    return {"CONTINUE": 1.0, "SLOW": 0.4, "STOP": 0.0, "REROUTE": 0.6}[command]


def _action(
    command: str, distance: float | None, risk: float, faults: frozenset[str]
) -> dict[str, Any]:
    reasons = {
        "STOP": f"Pedestrian detected at {distance}m with collision risk {risk:.2f}.",
        "SLOW": f"Pedestrian at {distance}m: slowing down, collision risk {risk:.2f}.",
        "REROUTE": "Aisle blocked by a pallet: taking the next aisle.",
        "CONTINUE": f"Path clear, collision risk {risk:.2f}.",
    }
    lost = {
        "STOP": "not needed" if command != "STOP" else "",
        "SLOW": "distance 1.5 m < 2.0 m" if command == "STOP" else "path clear",
        "REROUTE": "path not blocked",
        "CONTINUE": f"collision risk {risk:.2f} >= 0.2",
    }
    alternatives = [
        {"command": other, "score": round(0.5 - 0.1 * i, 2), "rejected_because": lost[other]}
        for i, other in enumerate(
            o for o in ("SLOW", "REROUTE", "CONTINUE", "STOP") if o != command
        )
    ]
    counterfactuals: list[dict[str, Any]] = []
    if "no_cf" not in faults:
        if command == "STOP":
            counterfactuals = [
                {
                    "factor": "ped_1.distance",
                    "comparison": ">=",
                    "threshold": 2.0,
                    "would_select": "SLOW",
                },
                {
                    "factor": "collision_risk",
                    "comparison": "<",
                    "threshold": 0.2,
                    "would_select": "CONTINUE",
                },
            ]
        elif command == "SLOW":
            counterfactuals = [
                {
                    "factor": "ped_1.distance",
                    "comparison": "<",
                    "threshold": 2.0,
                    "would_select": "STOP",
                }
            ]
        elif command == "CONTINUE":
            counterfactuals = [
                {
                    "factor": "collision_risk",
                    "comparison": ">=",
                    "threshold": 0.2,
                    "would_select": "SLOW",
                }
            ]
    factors = []
    if distance is not None:
        factors.append(
            {"node": "ped_1.distance", "name": "distance", "value": distance, "unit": "m"}
        )
    factors.append({"node": "collision_risk", "name": "collision_risk", "value": risk})
    if command == "REROUTE":
        factors.insert(0, {"node": "aisle_blocked", "name": "aisle_blocked", "value": True})
    return {
        "command": command,
        "parameters": {"speed": _speed(command)},
        "score": 0.9,
        "alternatives": alternatives,
        "rationale": {
            "text": reasons[command][: 12 if "truncated" in faults else None],
            "factors": factors,
            "truncated": "truncated" in faults,
        },
        "counterfactuals": counterfactuals,
        "counterfactuals_none_applicable": False,
        "tree": _tree(command),
    }


def _tree(command: str) -> dict[str, Any]:
    """The paper's Fig. 2 tree with the taken path for ``command``."""
    nodes = [
        {"id": "root", "label": "Decision point"},
        {"id": "ped", "label": "d_ped < 2m?", "test": "ped_1.distance < 2.0"},
        {"id": "path", "label": "Path clear?", "test": "not aisle_blocked"},
        {"id": "stop", "label": "STOP", "command": "STOP"},
        {"id": "slow", "label": "SLOW", "command": "SLOW"},
        {"id": "reroute", "label": "REROUTE", "command": "REROUTE"},
        {"id": "continue", "label": "CONTINUE", "command": "CONTINUE"},
    ]
    edges = [
        {"parent": "root", "child": "ped", "label": "ped detected"},
        {"parent": "root", "child": "path", "label": "no ped"},
        {"parent": "ped", "child": "stop", "label": "yes"},
        {"parent": "ped", "child": "slow", "label": "no"},
        {"parent": "path", "child": "reroute", "label": "no"},
        {"parent": "path", "child": "continue", "label": "yes"},
    ]
    via = "ped" if command in ("STOP", "SLOW") else "path"
    return {"nodes": nodes, "edges": edges, "taken_path": ["root", via, command.lower()]}


def write_log(
    path: Path,
    script: Iterable[Stretch] = DEFAULT_SCRIPT,
    *,
    t0_ns: int = T0_NS,
    robot_id: str = "amr-7",
    finish: bool = True,
    skip: Callable[[int], bool] | None = None,
    max_segment_s: float = 3600.0,
) -> Path:
    """Write ``script`` as a log at ``path`` (a .mcap file or a log root directory).

    ``skip(i)`` drops cycle ``i`` (it is aborted, so the next seal counts it as dropped);
    ``finish=False`` leaves the segment as a crashed robot would: no summary, no footer.
    A log root rotates to a new segment every ``max_segment_s`` of log time.
    """
    logger = AuditLogger(
        path,
        robot_id=robot_id,
        period_s=PERIOD_NS / 1e9,
        config=LoggerConfig(threaded=False, fsync_interval_s=None, max_segment_s=max_segment_s),
    )
    i = 0
    last_ref: EvidenceRef | None = None
    for part in script:
        for _ in range(part.cycles):
            c = logger.cycle(t0_ns + i * PERIOD_NS)
            if skip is not None and skip(i):
                c.abort()
            else:
                last_ref = fill_cycle(c, part.situation, part.faults, last_ref)
                c.commit()
            i += 1
    if finish:
        logger.close()
    else:
        # A crash: the file keeps every written batch but never gets its summary.
        simulate_crash(logger)
    return path


def rewrite_segment(
    src: Path,
    dst: Path,
    mutate: Callable[[RawMessage], bytes | None],
    *,
    chunk_size: int = 1 << 30,
    finish: bool = True,
) -> Path:
    """Copy a segment message by message with the plain ``mcap`` Writer, through ``mutate``.

    ``mutate`` returns the data to write (changed or not) or None to leave the message out:
    how a test tampers with a log. By default everything goes in one chunk, so no cycle is
    split. ``finish=False`` leaves the file as a killed writer does: every chunk written, no
    summary, no footer.
    """
    segment = open_segment(src)
    with open(dst, "wb") as f:
        writer = Writer(f, chunk_size=chunk_size)
        writer.start(profile="trace", library="tests")
        writer.add_metadata(SESSION_METADATA, segment.metadata[SESSION_METADATA])
        channels: dict[str, int] = {}
        for msg in segment.iter_messages():
            data = mutate(msg)
            if data is None:
                continue
            if msg.topic not in channels:
                schema = writer.register_schema(name=msg.topic, encoding="jsonschema", data=b"{}")
                channels[msg.topic] = writer.register_channel(
                    topic=msg.topic, message_encoding="json", schema_id=schema
                )
            writer.add_message(
                channels[msg.topic], msg.log_time_ns, data, msg.log_time_ns, sequence=msg.sequence
            )
        if finish:
            writer.finish()  # type: ignore[no-untyped-call]
        else:
            writer.flush()  # the last chunk reached the disk; the summary never did
    return dst


def t_ns(index: int, t0_ns: int = T0_NS) -> int:
    """Log time of cycle ``index`` of a fixture log, in ns."""
    return t0_ns + index * PERIOD_NS


def t_s(index: int, t0_ns: int = T0_NS) -> str:
    """The same as the CLI takes it: seconds in the log's clock, as text."""
    return f"{t_ns(index, t0_ns) / 1e9:.3f}"


@pytest.fixture()
def sample_log(tmp_path: Path) -> Path:
    """The default script as one finished segment (100 cycles, t = 100.0 .. 109.9 s)."""
    return write_log(tmp_path / "run.mcap")


@pytest.fixture()
def crashed_log(tmp_path: Path) -> Path:
    """The default script as an unfinished segment (no summary)."""
    return write_log(tmp_path / "crashed.mcap", finish=False)
