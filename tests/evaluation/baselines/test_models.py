"""The baselines' inputs and the numpy attention model."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from evaluation.baselines.attention import AttentionModel
from evaluation.baselines.features import FEATURES, MAX_TOKENS, TOKEN_FEATURES, read_decision_input


def _belief() -> dict[str, Any]:
    nodes = [
        {"id": "ped_1", "kind": "entity", "value": "person"},
        {"id": "ped_1.collision_risk", "kind": "state", "value": 0.1},
        {"id": "ped_1.distance", "kind": "state", "value": 6.0},
        {"id": "ped_2", "kind": "entity", "value": "person"},
        {"id": "ped_2.collision_risk", "kind": "state", "value": 0.7},
        {"id": "ped_2.distance", "kind": "state", "value": 1.5},
        {"id": "forklift_1", "kind": "entity", "value": "forklift"},
        {"id": "forklift_1.collision_risk", "kind": "state", "value": 0.3},
        {"id": "forklift_1.ttc", "kind": "state", "value": 4.0},
        {"id": "aisle_blocked", "kind": "state", "value": 0.2},
    ]
    return {"nodes": nodes, "edges": []}


def test_features_follow_the_policy_reader_riskiest_first_and_pad_absent_slots() -> None:
    d = read_decision_input(3, 300, {"command": "STOP"}, _belief())
    assert d is not None
    values = dict(zip(FEATURES, d.features.tolist(), strict=True))
    nodes = dict(zip(FEATURES, d.feature_nodes, strict=True))
    assert values["vehicle_risk"] == 0.3 and nodes["vehicle_ttc_s"] == "forklift_1.ttc"
    assert values["ped1_risk"] == 0.7 and nodes["ped1_distance_m"] == "ped_2.distance"
    assert values["ped2_risk"] == 0.1 and nodes["ped2_risk"] == "ped_1.collision_risk"
    assert nodes["ped3_risk"] is None and values["ped3_distance_m"] > 10
    assert nodes["aisle_blocked"] == "aisle_blocked"
    # tokens: movers by risk, then the aisle; each names the node it stands for
    assert d.token_nodes == ("ped_2", "forklift_1", "ped_1", "aisle_blocked")
    assert d.tokens.shape == (MAX_TOKENS, len(TOKEN_FEATURES))
    assert not d.tokens[len(d.token_nodes) :].any()


@pytest.mark.parametrize(
    ("action", "belief"),
    [(None, _belief()), ({"command": "STOP"}, None), ({"command": "FLY"}, _belief())],
)
def test_a_cycle_without_a_usable_action_or_belief_is_not_an_input(
    action: Any, belief: Any
) -> None:
    assert read_decision_input(0, 0, action, belief) is None


def _batch(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    x = rng.normal(size=(n, 4, 3))
    mask = np.ones((n, 4))
    mask[:, 3] = 0.0
    mask[: n // 2, 2] = 0.0
    # the label is decided by the token with the largest first feature
    y = np.argmax(np.where(mask > 0, x[:, :, 0], -np.inf), axis=1).astype(np.int64) % 2
    return x, mask, y


def test_attention_gradients_match_finite_differences() -> None:
    rng = np.random.default_rng(0)
    x, mask, y = _batch(rng, 6)
    model = AttentionModel(n_in=3, n_classes=2, hidden=4, seed=1)
    _, grads = model.loss_and_grads(x, mask, y)
    eps = 1e-6
    for array, grad in zip(model.params.arrays(), grads, strict=True):
        for idx in list(np.ndindex(array.shape))[:6]:
            keep = array[idx]
            array[idx] = keep + eps
            up, _ = model.loss_and_grads(x, mask, y)
            array[idx] = keep - eps
            down, _ = model.loss_and_grads(x, mask, y)
            array[idx] = keep
            assert grad[idx] == pytest.approx((up - down) / (2 * eps), rel=1e-4, abs=1e-7)


def test_padding_gets_no_attention_and_training_lowers_the_loss() -> None:
    rng = np.random.default_rng(2)
    x, mask, y = _batch(rng, 200)
    model = AttentionModel(n_in=3, n_classes=2, hidden=8, seed=0)
    before, _ = model.loss_and_grads(x, mask, y)
    after = model.fit(x, mask, y, steps=150)
    _, weights = model.attend(x, mask)
    assert np.allclose(weights.sum(axis=1), 1.0)
    assert not weights[mask == 0].any()
    assert after < before * 0.8
