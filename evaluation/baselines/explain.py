"""The learned policy and its explainers: LIME, SHAP and the attention model's weights.

The learned policy is a random forest imitating the rule policy (features: ``FEATURES``;
target: the logged command). LIME (``lime``'s tabular explainer, its default 5000 samples)
and SHAP (``shap.TreeExplainer``, exact for trees) explain its decisions; the attention
model explains its own through its attention weights. Each explanation becomes an
``ExplanationRecord`` citing the ``TOP_CITED`` strongest factors (docs/metrics.md).

scikit-learn, lime and shap are the ``[baselines]`` extra: imported here only, and this
module is imported only by ``trace-sim baselines``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from evaluation.baselines.attention import AttentionModel, FloatArray, IntArray
from evaluation.baselines.features import COMMAND_INDEX, FEATURES, MAX_TOKENS, DecisionInput
from evaluation.baselines.scoring import Citation, ExplanationRecord
from sim.policy import COMMANDS

__all__ = ["METHODS", "TOP_CITED", "Explainers", "train_explainers"]

METHODS = ("LIME", "SHAP", "attention")
TOP_CITED = 3
"""Factors an explanation cites: its strongest, as a reader of a LIME/SHAP bar chart would."""
LIME_SAMPLES = 5000
"""LIME's own default number of perturbed samples per explanation."""
# Explanation times are CPU time (``time.process_time``), as TRACE's are in ``cost``: the
# machine this runs on is usually shared, and wall time would measure the neighbours too.


def _shap() -> Any:
    # shap imports its plotting module, whose colour maps call a matplotlib function that
    # matplotlib has marked for deprecation; the warning is theirs, not ours.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=PendingDeprecationWarning)
        import shap

    return shap


def _matrix(inputs: Sequence[DecisionInput]) -> tuple[FloatArray, IntArray]:
    x = np.stack([d.features for d in inputs])
    y = np.asarray([COMMAND_INDEX[d.command] for d in inputs], dtype=np.int64)
    return x, y


def token_mask(inputs: Sequence[DecisionInput]) -> tuple[FloatArray, FloatArray]:
    """Stacked tokens and their mask (1 for a real token, 0 for padding)."""
    tokens = np.stack([d.tokens for d in inputs])
    counts = np.asarray([len(d.token_nodes) for d in inputs])
    mask = (np.arange(MAX_TOKENS)[None, :] < counts[:, None]).astype(np.float64)
    return tokens, mask


def _round(values: Sequence[float] | FloatArray) -> list[float]:
    return [round(float(v), 4) for v in values]


def _alternatives(proba: FloatArray, chosen: int) -> tuple[tuple[str, float], ...]:
    return tuple((COMMANDS[i], round(float(p), 4)) for i, p in enumerate(proba) if i != chosen)


def _top(
    weights: FloatArray, names: Sequence[str], nodes: Sequence[str | None]
) -> tuple[Citation, ...]:
    """The ``TOP_CITED`` largest |weights| that are not zero, strongest first."""
    order = np.argsort(-np.abs(weights), kind="stable")
    return tuple(
        Citation(names[i], round(float(weights[i]), 4), nodes[i])
        for i in order[:TOP_CITED]
        if weights[i] != 0.0
    )


@dataclass(slots=True)
class Explainers:
    """The trained models and explainers, ready to explain one decision at a time."""

    policy: Any
    """sklearn RandomForestClassifier over ``FEATURES``."""
    lime: Any
    shap: Any
    attention: AttentionModel
    seed: int

    def learned_accuracy(self, inputs: Sequence[DecisionInput]) -> float:
        x, y = _matrix(inputs)
        return float(np.mean(self.policy.predict(x) == y))

    def attention_accuracy(self, inputs: Sequence[DecisionInput]) -> float:
        tokens, mask = token_mask(inputs)
        _, y = _matrix(inputs)
        return float(np.mean(self.attention.predict_proba(tokens, mask).argmax(axis=1) == y))

    def explain(self, d: DecisionInput) -> list[ExplanationRecord]:
        """One record per method in ``METHODS`` for this decision."""
        return [self._lime(d), self._shap(d), self._attention(d)]

    def _proba(self, d: DecisionInput) -> tuple[FloatArray, int]:
        proba = self.policy.predict_proba(d.features[None, :])[0]
        full = np.zeros(len(COMMANDS))
        full[self.policy.classes_] = proba
        return full, int(full.argmax())

    def _lime(self, d: DecisionInput) -> ExplanationRecord:
        proba, label = self._proba(d)
        started = time.process_time()
        exp = self.lime.explain_instance(
            d.features,
            self._predict_full,
            labels=(label,),
            num_features=len(FEATURES),
            num_samples=LIME_SAMPLES,
        )
        seconds = time.process_time() - started
        weights = np.zeros(len(FEATURES))
        for i, w in exp.as_map()[label]:
            weights[int(i)] = float(w)
        return self._feature_record(
            "LIME", d=d, proba=proba, label=label, weights=weights, seconds=seconds, extra={}
        )

    def _shap(self, d: DecisionInput) -> ExplanationRecord:
        proba, label = self._proba(d)
        started = time.process_time()
        values = np.asarray(self.shap.shap_values(d.features[None, :]))
        seconds = time.process_time() - started
        # (1, features, classes) for a multi-class forest; classes are the forest's own
        column = int(np.searchsorted(self.policy.classes_, label))
        weights = values[0, :, column]
        base = float(np.atleast_1d(self.shap.expected_value)[column])
        return self._feature_record(
            "SHAP",
            d=d,
            proba=proba,
            label=label,
            weights=weights,
            seconds=seconds,
            extra={"base_value": round(base, 4)},
        )

    def _predict_full(self, x: FloatArray) -> FloatArray:
        """Probabilities over all of ``COMMANDS`` (a class absent from training gets 0)."""
        proba = self.policy.predict_proba(x)
        full = np.zeros((x.shape[0], len(COMMANDS)))
        full[:, self.policy.classes_] = proba
        return full

    def _feature_record(
        self,
        method: str,
        *,
        d: DecisionInput,
        proba: FloatArray,
        label: int,
        weights: FloatArray,
        seconds: float,
        extra: dict[str, Any],
    ) -> ExplanationRecord:
        return ExplanationRecord(
            method=method,
            cycle=d.cycle,
            t_ns=d.t_ns,
            command=COMMANDS[label],
            alternatives=_alternatives(proba, label),
            citations=_top(weights, FEATURES, d.feature_nodes),
            stored={
                "cycle": d.cycle,
                "command": COMMANDS[label],
                "probabilities": _round(proba),
                "inputs": _round(d.features),
                "attributions": _round(weights),
                "feature_nodes": list(d.feature_nodes),
                **extra,
            },
            seconds=seconds,
        )

    def _attention(self, d: DecisionInput) -> ExplanationRecord:
        tokens, mask = token_mask([d])
        started = time.process_time()
        proba_batch, attn = self.attention.attend(tokens, mask)
        seconds = time.process_time() - started
        proba = proba_batch[0]
        label = int(proba.argmax())
        n = len(d.token_nodes)
        weights = attn[0, :n]
        names = [f"token{i}:{node}" for i, node in enumerate(d.token_nodes)]
        return ExplanationRecord(
            method="attention",
            cycle=d.cycle,
            t_ns=d.t_ns,
            command=COMMANDS[label],
            alternatives=_alternatives(proba, label),
            citations=_top(weights, names, d.token_nodes),
            stored={
                "cycle": d.cycle,
                "command": COMMANDS[label],
                "probabilities": _round(proba),
                "tokens": [_round(row) for row in d.tokens[:n]],
                "weights": _round(weights),
                "token_nodes": list(d.token_nodes),
            },
            seconds=seconds,
        )


def train_explainers(inputs: Sequence[DecisionInput], seed: int) -> Explainers:
    """Fit the learned policy and the attention model on ``inputs``; build the explainers."""
    from lime.lime_tabular import LimeTabularExplainer
    from sklearn.ensemble import RandomForestClassifier

    x, y = _matrix(inputs)
    policy = RandomForestClassifier(n_estimators=50, max_depth=10, random_state=seed)
    policy.fit(x, y)
    lime = LimeTabularExplainer(
        x,
        feature_names=list(FEATURES),
        class_names=list(COMMANDS),
        discretize_continuous=True,
        random_state=seed,
    )
    explainer = _shap().TreeExplainer(policy)
    tokens, mask = token_mask(inputs)
    attention = AttentionModel(n_in=tokens.shape[2], n_classes=len(COMMANDS), seed=seed)
    attention.fit(tokens, mask, y)
    return Explainers(policy, lime, explainer, attention, seed)
