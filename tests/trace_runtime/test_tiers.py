"""Warm tier, catalog and logger resume across tiers, on logs written by the real logger.

``make_root`` (also used by the other tier tests) writes a log root whose cycles carry what
the warm tier must notice: execution flags, failed checks, command changes, a dropped
cycle, informational ``scenario:*`` flags, variable-length sensor readings and -0.0.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import orjson
import pytest

from trace_runtime import AuditLogger, LoggerConfig, open_log, open_segment
from trace_runtime.chain import digest
from trace_runtime.records import (
    GENESIS,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_CHECKPOINT,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
    ComplianceCheck,
)
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tiers import (
    CATALOG_NAME,
    WarmPolicy,
    compact,
    load_catalog,
    refresh_catalog,
    summarize,
)
from trace_runtime.tiers.warm import SUMMARY_TOPIC, warm_cycles

PERIOD_NS = 100_000_000
T0_NS = 1_000_000_000_000


def make_root(
    root: Path,
    cycles: int = 120,
    *,
    robot: str = "amr-1",
    t0_ns: int = T0_NS,
    segments: int = 1,
    flag_every: int = 40,
    drop_at: int | None = 70,
) -> Path:
    """Write ``segments`` hot segments of ``cycles`` cycles each under ``root``."""
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    index = 0
    for _ in range(segments):
        logger = AuditLogger(root, robot_id=robot, period_s=0.1, config=config)
        for _ in range(cycles):
            i = index
            index += 1
            builder = logger.cycle(t0_ns + i * PERIOD_NS)
            if drop_at is not None and i == drop_at:
                builder.abort()  # the next seal records the gap
                continue
            with builder as c:
                beams = [round(2.0 + 0.01 * ((i * 7 + k) % 13), 3) for k in range(3 + i % 5)]
                c.sensor("/sensors/lidar", {"ranges": beams, "cluster": i, "bias": -0.0})
                perception, belief, action, execution = synthetic_cycle(i, pedestrians=1 + i % 3)
                flags = ["scenario:routine"]
                checks = list(execution.checks)
                if flag_every and i % flag_every == flag_every // 2:
                    flags.append("near_miss")
                if flag_every and i % flag_every == 3:
                    checks.append(ComplianceCheck(rule="max_speed", passed=False, value=2.0))
                c.perception(perception)
                c.belief(belief)
                c.action(action)
                c.execution(execution.model_copy(update={"flags": flags, "checks": checks}))
        logger.close()
    return root


def hot_segment(root: Path) -> Path:
    return next((root / "hot").glob("*.mcap"))


def cycle_key(cycle: Any) -> tuple[Any, ...]:
    return (cycle.cycle, cycle.t_ns, cycle.payloads, cycle.sensors, cycle.summary)


# --- warm ------------------------------------------------------------------------------------


def test_warm_keeps_flagged_cycles_and_their_context_byte_for_byte(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log")
    hot = list(open_log(root).iter_cycles())
    policy = WarmPolicy(context_s=0.3)  # 3 cycles either side
    planned = list(warm_cycles(open_segment(hot_segment(root)).iter_messages(), policy, PERIOD_NS))
    compact(root, "warm", older_than_ns=0, warm=policy)
    warm = list(open_log(root).iter_cycles())
    assert [c.cycle for c in warm] == [c.cycle for c in hot]
    flagged = {w.number for w in planned if w.reasons}
    assert flagged, "the fixture must flag some cycles"
    # near_miss flags, failed checks, the dropped cycle and command changes are all flagged
    assert any("flag:near_miss" in w.reasons for w in planned)
    assert any("check:max_speed" in w.reasons for w in planned)
    assert any(r.startswith("gap:") for w in planned for r in w.reasons)
    assert not any("scenario" in r for w in planned for r in w.reasons)
    near = {n + d for n in flagged for d in range(-3, 4)}  # numbers = times here (0.1 s apart)
    for before, after in zip(hot, warm, strict=True):
        if after.cycle in near:
            assert cycle_key(after) == cycle_key(before)
        else:
            assert after.is_summary
            assert set(after.payloads) == {TOPIC_SEAL}
            assert after.payloads[TOPIC_SEAL] == before.payloads[TOPIC_SEAL]
            assert after.sensors == []


def test_warm_summary_keeps_what_explains_the_decision(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", flag_every=0, drop_at=None)
    hot = list(open_log(root).iter_cycles())
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_s=0))
    pairs = zip(hot, open_log(root).iter_cycles(), strict=True)
    summaries = 0
    for full, warm in pairs:
        if not warm.is_summary:
            continue
        summaries += 1
        action, belief = full.json(TOPIC_ACTION), full.json(TOPIC_BELIEF)
        s_action = warm.layer(TOPIC_ACTION)
        assert s_action["command"] == action["command"]
        assert s_action["rationale"]["factors"] == action["rationale"]["factors"]
        assert [a["command"] for a in s_action["alternatives"]] == [
            a["command"] for a in action["alternatives"]
        ]
        assert s_action["counterfactuals"] == action["counterfactuals"]
        assert "tree" not in s_action
        # belief: the factor nodes and every ancestor, nothing else
        s_belief = warm.layer(TOPIC_BELIEF)
        kept = {n["id"] for n in s_belief["nodes"]}
        factors = {f["node"] for f in action["rationale"]["factors"]}
        assert factors <= kept
        parents = {e["child"]: e["parent"] for e in belief["edges"]}
        for node in kept - factors:
            assert any(parents.get(f) == node for f in kept)
        # perception: the entities those nodes name, with their evidence refs
        s_perception = warm.layer(TOPIC_PERCEPTION)
        named = {n["entity"] for n in s_belief["nodes"] if n["kind"] == "entity"}
        assert {e["id"] for e in s_perception["entities"]} == named
        for entity in s_perception["entities"]:
            assert all("ref" in ev for ev in entity["evidence"])
        s_exec = warm.layer(TOPIC_EXECUTION)
        assert set(s_exec) == {"cycle", "t_ns", "intended", "actual", "deviation", "flags"}
    assert summaries > 50


def test_summarize_prunes_belief_to_ancestors_of_factors() -> None:
    layers = {
        TOPIC_ACTION: {
            "cycle": 1,
            "t_ns": 2,
            "command": "STOP",
            "rationale": {
                "text": "t",
                "factors": [{"node": "risk", "value": 0.9}],
                "truncated": False,
            },
        },
        TOPIC_BELIEF: {
            "cycle": 1,
            "t_ns": 2,
            "nodes": [
                {"id": "p1", "kind": "entity", "entity": "p1"},
                {"id": "d1", "kind": "state"},
                {"id": "risk", "kind": "state"},
                {"id": "other", "kind": "state"},
                {"id": "p2", "kind": "entity", "entity": "p2"},
            ],
            "edges": [
                {"parent": "p1", "child": "d1"},
                {"parent": "d1", "child": "risk"},
                {"parent": "p2", "child": "other"},
            ],
        },
        TOPIC_PERCEPTION: {
            "cycle": 1,
            "t_ns": 2,
            "entities": [
                {
                    "id": "p1",
                    "class": "person",
                    "velocity": [1, 0, 0],
                    "evidence": [
                        {"sensor": "lidar", "weight": 1.0, "region": {"kind": "beams"}, "ref": None}
                    ],
                },
                {"id": "p2", "class": "person", "evidence": []},
            ],
        },
    }
    out = summarize(layers)
    assert [n["id"] for n in out[TOPIC_BELIEF]["nodes"]] == ["p1", "d1", "risk"]
    assert len(out[TOPIC_BELIEF]["edges"]) == 2
    assert out[TOPIC_PERCEPTION]["entities"] == [
        {
            "id": "p1",
            "class": "person",
            "evidence": [{"sensor": "lidar", "weight": 1.0, "ref": None}],
        }
    ]


def test_warm_keeps_checkpoints_and_says_it_is_lossy(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=250)
    source = open_segment(hot_segment(root))
    checkpoints = [m for m in source.iter_messages() if m.topic == TOPIC_CHECKPOINT]
    assert checkpoints
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_s=0))
    warm = open_segment(next((root / "warm").glob("*.mcap")))
    assert [m for m in warm.iter_messages() if m.topic == TOPIC_CHECKPOINT] == checkpoints
    meta = warm.metadata["trace.tier"]
    assert meta["lossy"] == "true" and "summar" in meta["note"]
    assert warm.session.tier == "warm"
    assert any(m.topic == SUMMARY_TOPIC for m in warm.iter_messages())


def test_warm_keep_readings_keeps_referenced_sensor_messages(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", flag_every=0, drop_at=None)
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_s=0, keep_readings=True))
    summaries = [c for c in open_log(root).iter_cycles() if c.is_summary]
    assert summaries
    for cycle in summaries:
        refs = {
            (ev["ref"]["topic"], ev["ref"]["log_time_ns"])
            for e in cycle.layer(TOPIC_PERCEPTION)["entities"]
            for ev in e["evidence"]
            if ev["ref"]
        }
        assert {(m.topic, m.log_time_ns) for m in cycle.sensors} <= refs


# --- catalog -----------------------------------------------------------------------------------


def test_catalog_is_rebuilt_from_the_files(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=30, segments=3)
    assert load_catalog(root) is None
    catalog = refresh_catalog(root)
    assert (root / CATALOG_NAME).exists()
    assert [(e.tier, e.segment) for e in catalog.entries] == [("hot", 0), ("hot", 1), ("hot", 2)]
    log = open_log(root)
    for entry, segment in zip(catalog.entries, log.segments, strict=True):
        cycles = [c for c in segment.iter_cycles() if c.sealed]
        assert entry.cycles == len(cycles)
        assert (entry.first_cycle, entry.last_cycle) == (cycles[0].cycle, cycles[-1].cycle)
        assert entry.first_seal == digest(cycles[0].payloads[TOPIC_SEAL])
        assert entry.last_seal == digest(cycles[-1].payloads[TOPIC_SEAL])
        assert entry.prev_seal == segment.session.prev_seal
        assert (entry.start_ns, entry.end_ns) == (segment.info.start_ns, segment.info.end_ns)
        assert entry.bytes == segment.path.stat().st_size
    # the chain runs through the catalog: each segment starts where the previous one ended
    assert catalog.entries[0].prev_seal == GENESIS
    assert catalog.entries[1].prev_seal == catalog.entries[0].last_seal
    # compacting changes the rows, not the facts; a lost catalog comes back the same
    compact(root, "cold", older_than_ns=0, sources=["hot"])
    cold = load_catalog(root)
    assert cold is not None
    assert [e.tier for e in cold.entries] == ["cold"] * 3
    for before, after in zip(catalog.entries, cold.entries, strict=True):
        assert (after.first_seal, after.last_seal, after.cycles, after.start_ns, after.end_ns) == (
            before.first_seal,
            before.last_seal,
            before.cycles,
            before.start_ns,
            before.end_ns,
        )
    (root / CATALOG_NAME).unlink()
    rebuilt = refresh_catalog(root)
    assert [(e.path, e.sha256) for e in rebuilt.entries] == [
        (e.path, e.sha256) for e in cold.entries
    ]
    assert not list(root.glob("*.partial"))


def test_catalog_lists_unreadable_files_as_problems(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=10)
    (root / "hot" / "junk_000001.mcap").write_bytes(b"not an mcap file")
    catalog = refresh_catalog(root, write=False)
    assert len(catalog.entries) == 1
    assert catalog.problems and "junk_000001.mcap" in catalog.problems[0]
    assert not (root / CATALOG_NAME).exists()


# --- logger resume across tiers --------------------------------------------------------------


@pytest.mark.parametrize("tier", ["warm", "cold"])
def test_logger_resumes_the_chain_from_compacted_segments(tmp_path: Path, tier: str) -> None:
    root = make_root(tmp_path / "log", cycles=20, segments=2)
    last = list(open_log(root).iter_cycles())[-1]
    compact(root, tier, older_than_ns=0, retention_ns=None)
    assert not list((root / "hot").glob("*.mcap"))
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    with AuditLogger(root, robot_id="amr-1", period_s=0.1, config=config) as logger:
        p, b, a, e = synthetic_cycle(99)
        logger.log_cycle(T0_NS + 10**11, perception=p, belief=b, action=a, execution=e)
    new = open_segment(next((root / "hot").glob("*.mcap")))
    assert new.session.segment == 2
    assert new.session.prev_seal == digest(last.payloads[TOPIC_SEAL])
    first = next(new.iter_cycles())
    assert first.cycle == last.cycle + 1
    assert orjson.loads(first.payloads[TOPIC_SEAL])["prev"] == digest(last.payloads[TOPIC_SEAL])


def test_resume_ignores_other_robots_with_a_common_prefix(tmp_path: Path) -> None:
    make_root(tmp_path / "log", cycles=5, robot="amr_2")
    shutil.copytree(tmp_path / "log", tmp_path / "copy")
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    with AuditLogger(tmp_path / "copy", robot_id="amr", period_s=0.1, config=config) as logger:
        assert logger._session.segment == 0
        assert logger._session.prev_seal == GENESIS
