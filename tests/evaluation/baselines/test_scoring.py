"""The metrics applied to hand-made explanation records whose answers are known."""

from __future__ import annotations

import hashlib
from typing import Any

import orjson
import pytest

from evaluation.baselines.scoring import Citation, ExplanationRecord, as_action, score_explanation
from trace_audit.chains import SensorWindow
from trace_runtime.encoding.cycles import RawMessage

T_NS = 1_000_000_000
SCAN = b'{"ranges":[1.0,2.0]}'


def _ref(data: bytes = SCAN) -> dict[str, Any]:
    return {
        "topic": "/sensors/lidar",
        "log_time_ns": T_NS,
        "sequence": 0,
        "digest": hashlib.sha256(data).hexdigest(),
    }


def _scene(ref: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """One pedestrian seen by the LiDAR; an aisle state logged without its parent edge."""
    belief = {
        "nodes": [
            {"id": "ped_1", "kind": "entity", "entity": "ped_1", "value": "person"},
            {"id": "ped_1.distance", "kind": "state", "value": 1.5},
            {"id": "ped_1.collision_risk", "kind": "state", "value": 0.8},
            {"id": "aisle_blocked", "kind": "state", "value": 0.0},
        ],
        "edges": [
            {"parent": "ped_1", "child": "ped_1.distance"},
            {"parent": "ped_1.distance", "child": "ped_1.collision_risk"},
        ],
    }
    perception = {
        "entities": [
            {
                "id": "ped_1",
                "class": "person",
                "evidence": [{"sensor": "lidar", "weight": 1.0, "ref": ref or _ref()}],
            }
        ]
    }
    return belief, perception


def _window() -> SensorWindow:
    window = SensorWindow(0)
    window.push([RawMessage("/sensors/lidar", 0, T_NS, SCAN)])
    return window


def _record(*citations: Citation, **kw: Any) -> ExplanationRecord:
    fields: dict[str, Any] = {
        "method": "hand",
        "cycle": 10,
        "t_ns": T_NS,
        "command": "STOP",
        "alternatives": (("SLOW", 0.1), ("CONTINUE", 0.0)),
        "citations": citations,
    }
    fields.update(kw)
    return ExplanationRecord(**fields)


RISK = Citation("ped1_risk", 0.7, "ped_1.collision_risk")
ENTITY = Citation("token0:ped_1", 0.6, "ped_1")
PADDING = Citation("ped2_risk", -0.2, None)
AISLE = Citation("aisle_blocked", 0.1, "aisle_blocked")


def _score(record: ExplanationRecord, ref: dict[str, Any] | None = None) -> Any:
    belief, perception = _scene(ref)
    return score_explanation(record, belief, perception, _window())


def test_a_cited_state_and_a_cited_entity_both_trace_to_the_reading() -> None:
    score = _score(_record(RISK, ENTITY))
    assert (score.et, score.et_partial) == (1.0, 1.0)
    assert not [p for p in score.problems if p.startswith("ET")]


def test_a_padding_feature_has_no_link_and_counts_as_depth_zero() -> None:
    score = _score(_record(RISK, PADDING))
    assert score.et == 0.5
    assert score.et_partial == pytest.approx((1.0 + 0.0) / 2)
    assert any("ped2_risk: factor_node missing" in p for p in score.problems)


def test_a_state_without_its_belief_edge_stops_at_depth_one_of_five() -> None:
    score = _score(_record(AISLE))
    assert score.et == 0.0
    assert score.et_partial == pytest.approx(1 / 5)


def test_a_ref_whose_digest_does_not_match_stops_at_depth_four() -> None:
    score = _score(_record(RISK, ENTITY), ref=_ref(b"other bytes"))
    assert score.et == 0.0
    # the state factor reaches 4 of 5 levels, the entity factor 3 of 4
    assert score.et_partial == pytest.approx((4 / 5 + 3 / 4) / 2)


def test_an_explanation_citing_nothing_has_no_et_and_no_dr() -> None:
    score = _score(_record())
    assert (score.et, score.et_partial, score.dr) == (0.0, 0.0, False)
    assert "DR: rationale names no factors" in score.problems


@pytest.mark.parametrize(
    ("changes", "dr", "missing"),
    [
        ({"counterfactuals": ({"factor": "ped_1.collision_risk", "would_select": "SLOW"},)},
         True, None),
        ({"counterfactuals_none_applicable": True}, True, None),
        ({}, False, "DR: no counterfactuals and not declared none-applicable"),
        ({"alternatives": (), "counterfactuals_none_applicable": True}, False,
         "DR: no alternatives logged"),
        ({"command": None}, False, "DR: action not logged"),
    ],
)  # fmt: skip
def test_dr_needs_action_alternatives_factors_and_counterfactuals(
    changes: dict[str, Any], dr: bool, missing: str | None
) -> None:
    score = _score(_record(RISK, **changes))
    assert score.dr is dr
    if missing is not None:
        assert missing in score.problems


def test_bytes_are_the_compact_json_of_what_the_method_stores() -> None:
    stored = {"cycle": 10, "attributions": [0.5, -0.25]}
    score = _score(_record(RISK, stored=stored))
    assert score.bytes == len(b'{"cycle":10,"attributions":[0.5,-0.25]}')
    assert score.bytes == len(orjson.dumps(stored))


def test_the_record_in_action_shape_names_each_citation_as_a_factor() -> None:
    action = as_action(_record(RISK, PADDING))
    assert [f["node"] for f in action["rationale"]["factors"]] == ["ped_1.collision_risk", None]
    assert [a["command"] for a in action["alternatives"]] == ["SLOW", "CONTINUE"]
