"""What the learned baselines see of a logged decision: a feature vector and entity tokens.

Both are read off the cycle's logged belief graph, through the rule policy's own public
reader (``PolicyInput.from_nodes``), so they follow whatever the policy treats as a
pedestrian, a vehicle and the aisle state. Every feature and token keeps the id of the belief
node it was read from: that is the documented link an explanation can be followed through to
sensor evidence (docs/metrics.md, "Explanation baselines"). A padding slot (no such entity
this cycle) has no node.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from sim.policy import COMMANDS, PolicyInput

__all__ = [
    "COMMAND_INDEX",
    "FEATURES",
    "MAX_TOKENS",
    "TOKEN_FEATURES",
    "DecisionInput",
    "read_decision_input",
]

PEDESTRIAN_SLOTS = 3
FEATURES: tuple[str, ...] = (
    "vehicle_risk",
    "vehicle_ttc_s",
    *(
        name
        for k in range(1, PEDESTRIAN_SLOTS + 1)
        for name in (f"ped{k}_risk", f"ped{k}_distance_m")
    ),
    "aisle_blocked",
)
# Padding reads as "nothing there": no risk, and far beyond every threshold the policy tests.
_FAR = 20.0
_PAD = {"risk": 0.0, "distance": _FAR, "ttc": _FAR}

TOKEN_FEATURES = ("is_pedestrian", "is_vehicle", "is_aisle", "risk", "range_10m")
MAX_TOKENS = 8
"""Entity tokens the attention model takes (pedestrians and vehicles by risk, then the aisle)."""

COMMAND_INDEX = {command: i for i, command in enumerate(COMMANDS)}

FloatArray = npt.NDArray[np.float64]


class _Node(NamedTuple):
    id: str
    value: object


@dataclass(frozen=True, slots=True)
class DecisionInput:
    """One logged decision as the baselines see it, with the node behind every input."""

    cycle: int
    t_ns: int
    command: str
    """The command the rule policy chose, as logged (the learned policy's target)."""
    features: FloatArray
    feature_nodes: tuple[str | None, ...]
    tokens: FloatArray
    """(MAX_TOKENS, len(TOKEN_FEATURES)); rows past ``len(token_nodes)`` are zero padding."""
    token_nodes: tuple[str, ...]


def _number(values: Mapping[str, object], node: str, default: float) -> float:
    value = values.get(node)
    return float(value) if isinstance(value, (int, float)) else default


def read_decision_input(cycle: int, t_ns: int, action: Any, belief: Any) -> DecisionInput | None:
    """The baselines' view of one logged cycle; None when its action or belief is not logged."""
    if not isinstance(action, dict) or not isinstance(belief, dict):
        return None
    command = action.get("command")
    if command not in COMMAND_INDEX:
        return None
    raw_nodes = [n for n in belief.get("nodes") or () if isinstance(n, dict)]
    nodes = [_Node(str(n.get("id")), n.get("value")) for n in raw_nodes]
    values = {n.id: n.value for n in nodes}
    inp = PolicyInput.from_nodes(nodes)

    def risk_of(item: tuple[str, str, str]) -> float:
        return _number(values, item[1], 0.0)

    vehicles = sorted(inp.vehicles, key=risk_of, reverse=True)
    peds = sorted(inp.peds, key=risk_of, reverse=True)
    feats: list[float] = []
    links: list[str | None] = []
    if vehicles:
        _, risk, ttc = vehicles[0]
        feats += [_number(values, risk, 0.0), _number(values, ttc, _FAR)]
        links += [risk, ttc]
    else:
        feats += [_PAD["risk"], _PAD["ttc"]]
        links += [None, None]
    for k in range(PEDESTRIAN_SLOTS):
        if k < len(peds):
            _, risk, dist = peds[k]
            feats += [_number(values, risk, 0.0), _number(values, dist, _FAR)]
            links += [risk, dist]
        else:
            feats += [_PAD["risk"], _PAD["distance"]]
            links += [None, None]
    aisle_known = inp.aisle in values
    feats.append(_number(values, inp.aisle, 0.0))
    links.append(inp.aisle if aisle_known else None)
    tokens, token_nodes = _tokens(values, peds, vehicles, inp.aisle if aisle_known else None)
    return DecisionInput(
        cycle=cycle,
        t_ns=t_ns,
        command=str(command),
        features=np.asarray(feats, dtype=np.float64),
        feature_nodes=tuple(links),
        tokens=tokens,
        token_nodes=token_nodes,
    )


def _tokens(
    values: Mapping[str, object],
    peds: Sequence[tuple[str, str, str]],
    vehicles: Sequence[tuple[str, str, str]],
    aisle: str | None,
) -> tuple[FloatArray, tuple[str, ...]]:
    """One token per pedestrian and vehicle (linked to its entity node), and the aisle state."""
    rows: list[list[float]] = []
    links: list[str] = []
    room = MAX_TOKENS - (1 if aisle is not None else 0)
    movers = [(True, p) for p in peds] + [(False, v) for v in vehicles]
    movers.sort(key=lambda m: _number(values, m[1][1], 0.0), reverse=True)
    for is_ped, (entity, risk, rng) in movers[:room]:
        rows.append(
            [
                1.0 if is_ped else 0.0,
                0.0 if is_ped else 1.0,
                0.0,
                _number(values, risk, 0.0),
                _number(values, rng, _FAR) / 10.0,
            ]
        )
        links.append(entity)
    if aisle is not None:
        rows.append([0.0, 0.0, 1.0, _number(values, aisle, 0.0), 0.0])
        links.append(aisle)
    tokens = np.zeros((MAX_TOKENS, len(TOKEN_FEATURES)), dtype=np.float64)
    if rows:
        tokens[: len(rows)] = np.asarray(rows, dtype=np.float64)
    return tokens, tuple(links)
