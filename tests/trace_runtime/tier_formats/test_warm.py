"""The warm tier on logs written by the real logger: flagged cycles and their context kept
byte for byte, routine cycles summarised, checkpoints kept.
"""

from __future__ import annotations

from pathlib import Path

from tests.trace_runtime.tier_logs import PERIOD_NS, cycle_key, hot_segment, make_root
from trace_runtime import open_log, open_segment
from trace_runtime.records import (
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_CHECKPOINT,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)
from trace_runtime.tier_formats.warm import SUMMARY_TOPIC, warm_cycles
from trace_runtime.tiers import (
    WarmPolicy,
    compact,
    summarize,
)

# --- warm ------------------------------------------------------------------------------------


def test_warm_keeps_flagged_cycles_and_their_context_byte_for_byte(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log")
    hot = list(open_log(root).iter_cycles())
    policy = WarmPolicy(context_ns=300_000_000)  # 3 cycles either side
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
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_ns=0))
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
        # execution: the whole record, whatever fields the profile gives it
        assert warm.layer(TOPIC_EXECUTION) == full.json(TOPIC_EXECUTION)
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
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_ns=0))
    warm = open_segment(next((root / "warm").glob("*.mcap")))
    assert [m for m in warm.iter_messages() if m.topic == TOPIC_CHECKPOINT] == checkpoints
    meta = warm.metadata["trace.tier"]
    assert meta["lossy"] == "true" and "summar" in meta["note"]
    assert warm.session.tier == "warm"
    assert any(m.topic == SUMMARY_TOPIC for m in warm.iter_messages())


def test_warm_keep_readings_keeps_referenced_sensor_messages(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", flag_every=0, drop_at=None)
    compact(root, "warm", older_than_ns=0, warm=WarmPolicy(context_ns=0, keep_readings=True))
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
