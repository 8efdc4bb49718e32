"""The causal chain walker: documented depth, missing links, ref resolution, the window."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import orjson
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from trace_audit.chains import (
    EXPECTED_DEPTH_ENTITY,
    EXPECTED_DEPTH_STATE,
    FactorChain,
    Link,
    SensorWindow,
    label_chain,
    score_layers,
    trace_cycle,
    trace_layers,
)
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.reading.logset import open_log

LIDAR = b'{"ranges":[1.5,1.52]}'


def _msg(
    topic: str = "/sensors/lidar", t_ns: int = 100, seq: int = 0, data: bytes = LIDAR
) -> RawMessage:
    return RawMessage(topic, seq, t_ns, data)


def _ref(
    t_ns: int = 100, seq: int | None = 0, data: bytes | None = LIDAR, topic: str = "/sensors/lidar"
) -> dict[str, Any]:
    return {
        "topic": topic,
        "log_time_ns": t_ns,
        "sequence": seq,
        "digest": None if data is None else hashlib.sha256(data).hexdigest(),
    }


def _layers(
    ref: dict[str, Any] | None = None, *, edges: bool = True, factor: str = "risk"
) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    perception = {
        "entities": [
            {
                "id": "ped_1",
                "class": "person",
                "evidence": [
                    {"sensor": "lidar", "weight": 1.0, "ref": _ref() if ref is None else ref}
                ],
            }
        ]
    }
    belief = {
        "nodes": [
            {"id": "ped_1", "kind": "entity", "entity": "ped_1", "p": 0.9},
            {"id": "dist", "kind": "state", "p": 0.9, "value": 1.5},
            {"id": "risk", "kind": "state", "p": 0.7, "value": 0.7},
        ],
        "edges": (
            [
                {"parent": "ped_1", "child": "dist", "p": 0.9, "rule": "range"},
                {"parent": "dist", "child": "risk", "p": 0.8, "rule": "ttc"},
            ]
            if edges
            else []
        ),
    }
    action = {
        "command": "STOP",
        "rationale": {"text": "x", "factors": [{"node": factor, "value": 0.7}]},
    }
    return action, belief, perception


def _window(*msgs: RawMessage) -> SensorWindow:
    window = SensorWindow(0)
    window.push(list(msgs))
    return window


def test_full_chain_through_two_belief_edges_is_traceable() -> None:
    action, belief, perception = _layers()
    d = trace_layers(1, 100, action, belief, perception, window=_window(_msg()))
    (chain,) = d.factors
    assert [link.level for link in chain.links] == [
        "factor_node",
        "belief_path",
        "entity",
        "evidence_ref",
        "sensor_reading",
    ]
    assert all(link.documented for link in chain.links)
    assert chain.links[1].ref == "risk <- dist <- ped_1"
    assert chain.depth == chain.expected_depth == EXPECTED_DEPTH_STATE
    assert d.et == 1.0 and d.et_partial == 1.0 and d.fully_traceable


def test_entity_factor_has_the_shorter_expected_chain() -> None:
    action, belief, perception = _layers(factor="ped_1")
    (chain,) = trace_layers(1, 100, action, belief, perception, window=_window(_msg())).factors
    assert chain.expected_depth == EXPECTED_DEPTH_ENTITY
    assert [link.level for link in chain.links] == [
        "factor_node",
        "entity",
        "evidence_ref",
        "sensor_reading",
    ]
    assert chain.traceable


def test_missing_edge_breaks_at_belief_path_and_marks_the_rest_missing() -> None:
    action, belief, perception = _layers(edges=False)
    d = trace_layers(1, 100, action, belief, perception, window=_window(_msg()))
    (chain,) = d.factors
    assert [link.documented for link in chain.links] == [True, False, False, False, False]
    assert chain.depth == 1 and d.et == 0.0 and d.et_partial == pytest.approx(1 / 5)
    assert chain.missing is not None and chain.missing.level == "belief_path"


@pytest.mark.parametrize(
    ("ref", "msg", "depth", "why"),
    [
        ({"null": True}, _msg(), 3, "has a ref"),
        (_ref(t_ns=999), _msg(), 4, "no /sensors/lidar message"),
        (_ref(seq=7), _msg(), 4, "sequence 7"),
        (_ref(data=b"other"), _msg(), 4, "digest"),
        (_ref(seq=None, data=None), _msg(seq=42), 5, ""),
    ],
)
def test_evidence_ref_resolution(
    ref: dict[str, Any], msg: RawMessage, depth: int, why: str
) -> None:
    action, belief, perception = _layers(ref)
    if "null" in ref:
        perception["entities"][0]["evidence"][0]["ref"] = None
    (chain,) = trace_layers(1, 100, action, belief, perception, window=_window(msg)).factors
    assert chain.depth == depth
    if why:
        assert chain.missing is not None and why in chain.missing.detail


def test_unknown_factor_node_and_missing_layers_give_depth_zero_or_stop_early() -> None:
    action, belief, perception = _layers(factor="nope")
    (chain,) = trace_layers(1, 100, action, belief, perception, window=_window(_msg())).factors
    assert chain.depth == 0 and chain.expected_depth == EXPECTED_DEPTH_STATE
    assert len(chain.links) == 5
    action, belief, _ = _layers()
    (chain,) = trace_layers(1, 100, action, belief, None, window=_window(_msg())).factors
    assert chain.depth == 2 and chain.missing is not None
    assert chain.missing.detail == "perception layer not logged"


def test_decision_without_action_or_factors_scores_zero() -> None:
    d = trace_layers(1, 100, None, None, None, window=_window())
    assert (d.et, d.et_partial, d.reason) == (0.0, 0.0, "action not logged")
    d = trace_layers(1, 100, {"rationale": {"factors": []}}, None, None, window=_window())
    assert d.reason == "action names no factors" and not d.fully_traceable


def test_deepest_route_wins_when_one_parent_is_undocumented() -> None:
    action, belief, perception = _layers()
    belief["nodes"].append({"id": "ghost", "kind": "entity", "entity": "gone", "p": 1.0})
    belief["edges"].insert(0, {"parent": "ghost", "child": "risk", "p": 1.0, "rule": "r"})
    (chain,) = trace_layers(1, 100, action, belief, perception, window=_window(_msg())).factors
    assert chain.traceable and chain.links[1].ref == "risk <- dist <- ped_1"


def test_et_is_share_of_traceable_factors() -> None:
    action, belief, perception = _layers()
    action["rationale"]["factors"].append({"node": "ped_1", "value": 1})
    action["rationale"]["factors"].append({"node": "missing", "value": 1})
    d = trace_layers(1, 100, action, belief, perception, window=_window(_msg()))
    assert d.et == pytest.approx(2 / 3)
    assert d.et_partial == pytest.approx((1 + 1 + 0) / 3)


def test_window_is_bounded_in_cycles() -> None:
    window = SensorWindow(2)
    window.push([_msg(t_ns=1)])
    assert window.resolve(_ref(t_ns=1)) == ""
    window.push([])
    window.push([])
    assert window.resolve(_ref(t_ns=1)) == ""  # current cycle + 2 before it
    window.push([])
    assert "no /sensors/lidar message" in window.resolve(_ref(t_ns=1))


def test_on_a_logged_cycle(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with AuditLogger(path, robot_id="r1", config=LoggerConfig(threaded=False)) as logger:
        for i in range(3):
            with logger.cycle(1_000_000_000 + i * 100_000_000) as c:
                ref = c.sensor("/sensors/lidar", {"ranges": [1.5]})
                action, belief, perception = _layers(orjson.loads(ref.model_dump_json()))
                action.update(alternatives=[], counterfactuals=[])
                c.perception(
                    perception
                    | {
                        "entities": [
                            {
                                **perception["entities"][0],
                                "pose": {"position": [1, 0, 0]},
                                "confidence": {"person": 0.9},
                            }
                        ]
                    }
                )
                c.belief(belief)
                c.action(action)
    cycles = list(open_log(path).iter_cycles())
    assert len(cycles) == 3
    for cycle in cycles:
        assert trace_cycle(cycle).fully_traceable


# --- properties: the fast score and the full walk agree, and nothing malformed raises ----

_IDS = st.sampled_from(["a", "b", "c", "d", "e", "f"])


@st.composite
def _decision(draw: st.DrawFn) -> tuple[Any, Any, Any, list[RawMessage]]:
    kinds = draw(st.dictionaries(_IDS, st.sampled_from(["entity", "state"]), max_size=6))
    nodes = [
        {
            "id": i,
            "kind": k,
            "entity": draw(st.sampled_from([None, i, "x"])) if k == "entity" else None,
            "p": 1.0,
        }
        for i, k in kinds.items()
    ]
    edges = [
        {"parent": p, "child": c, "p": 1.0, "rule": "r"}
        for p, c in draw(st.lists(st.tuples(_IDS, _IDS), max_size=10))
    ]
    msgs = [_msg(t_ns=t, seq=t) for t in range(3)]
    entities = []
    for entity_id in draw(st.lists(st.sampled_from(["a", "b", "c", "x"]), max_size=4, unique=True)):
        evidence = []
        for _ in range(draw(st.integers(0, 2))):
            t = draw(st.integers(0, 4))
            ref = draw(
                st.sampled_from(
                    [
                        None,
                        _ref(t_ns=t, seq=t),
                        _ref(t_ns=t, seq=t + 1),
                        _ref(t_ns=t, seq=None, data=b"x"),
                    ]
                )
            )
            evidence.append({"sensor": "lidar", "weight": 1.0, "ref": ref})
        entities.append({"id": entity_id, "evidence": evidence})
    factors = [
        {"node": n} for n in draw(st.lists(st.sampled_from(["a", "b", "c", "d", "zz"]), max_size=4))
    ]
    action = {"command": "STOP", "rationale": {"factors": factors}}
    return action, {"nodes": nodes, "edges": edges}, {"entities": entities}, msgs


@settings(max_examples=300, deadline=None)
@given(_decision())
def test_score_layers_matches_trace_layers(decision: tuple[Any, Any, Any, Any]) -> None:
    action, belief, perception, msgs = decision
    window = _window(*msgs)
    full = trace_layers(0, 0, action, belief, perception, window=window)
    fast = score_layers(action, belief, perception, window=window)
    assert (fast.et, fast.et_partial) == pytest.approx((full.et, full.et_partial))
    assert fast.fully_traceable == full.fully_traceable
    for chain in full.factors:
        documented = [link.documented for link in chain.links]
        assert chain.depth == [*documented, False].index(False)
        assert len(chain.links) == chain.expected_depth


_JUNK = st.recursive(
    st.none() | st.booleans() | st.integers() | st.text(max_size=3),
    lambda inner: (
        st.lists(inner, max_size=3)
        | st.dictionaries(
            st.sampled_from(
                [
                    "id",
                    "kind",
                    "entity",
                    "nodes",
                    "edges",
                    "parent",
                    "child",
                    "entities",
                    "evidence",
                    "ref",
                    "topic",
                    "log_time_ns",
                    "rationale",
                    "factors",
                    "node",
                ]
            ),
            inner,
            max_size=4,
        )
    ),
    max_leaves=12,
)


@settings(max_examples=300, deadline=None)
@given(_JUNK, _JUNK, _JUNK)
@example({"rationale": {"factors": True}}, None, None)  # once found: factors not a list
def test_malformed_layers_never_raise(action: Any, belief: Any, perception: Any) -> None:
    window = _window(_msg())
    full = trace_layers(0, 0, action, belief, perception, window=window)
    fast = score_layers(action, belief, perception, window=window)
    assert (fast.et, fast.et_partial) == pytest.approx((full.et, full.et_partial))


def test_a_chain_is_labelled_bottom_up_in_its_causal_graphs_words() -> None:
    """label_chain: the path of node labels (the belief entity node left out), each link's
    label, the belief path with its rules, and which links are placeholders or unreached."""
    unreached = "not reached: the chain is broken above"
    chain = FactorChain(
        "risk",
        "risk",
        (
            Link("factor_node", True, "risk"),
            Link("belief_path", True, "risk <- ped"),
            Link("entity", True, "ped_1"),
            Link("evidence_ref", False, "ped_1", "entity 'ped_1' has no evidence"),
            Link("sensor_reading", False, "", unreached),
        ),
        3,
        EXPECTED_DEPTH_STATE,
    )
    placeholder = "missing:evidence_ref:entity:ped_1"
    graph = {
        "nodes": [
            {"id": "action", "label": "STOP"},
            {"id": "belief:risk", "label": "risk = 0.9"},
            {"id": "belief:ped", "label": "ped [ped_1]", "belief_kind": "entity"},
            {"id": "entity:ped_1", "label": "person ped_1"},
            {"id": placeholder, "label": "? evidence (not documented)"},
        ],
        "edges": [
            {"source": "belief:risk", "target": "action", "level": "factor_node"},
            {"source": "belief:ped", "target": "belief:risk", "level": "belief_path"},
            {"source": "entity:ped_1", "target": "belief:ped", "level": "entity"},
            {"source": placeholder, "target": "entity:ped_1", "level": "evidence_ref"},
        ],
    }
    for edge in graph["edges"]:
        edge["factors"] = ["risk"]
    graph["edges"][1]["rule"] = "near"

    labelled = label_chain(chain, graph, "STOP")

    assert labelled.path == ("? evidence (not documented)", "person ped_1", "risk = 0.9", "STOP")
    assert [link.link.level for link in labelled.links] == [
        "sensor_reading",
        "evidence_ref",
        "entity",
        "belief_path",
        "factor_node",
    ]
    assert [link.what for link in labelled.links] == [
        "",
        "? evidence (not documented)",
        "person ped_1",
        "ped -> risk (rules: near)",
        "risk = 0.9 -> STOP",
    ]
    assert [link.reached for link in labelled.links] == [False, True, True, True, True]
    assert [link.placeholder for link in labelled.links] == [False, True, False, False, False]
