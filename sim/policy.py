"""Layer 3 policy: the paper's Fig. 2 decision tree, extended with a vehicle branch.

::

    root: vehicle on a collision course?  (max vehicle collision_risk >= 0.5)
      yes -> vehicle_close: ttc < 3.0 s?        yes -> STOP      no -> REROUTE
      no  -> ped_in_path: pedestrian in path? (max pedestrian collision_risk >= 0.2)
               yes -> ped_close: d_ped < 2.0 m?  yes -> STOP      no -> SLOW
               no  -> path_clear: aisle_blocked < 0.5?  yes -> CONTINUE  no -> REROUTE

The policy is a pure function of belief node values, so it can be re-run on a logged
belief graph (``PolicyInput.from_nodes``) and probed with interventions on single nodes.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

STOP, SLOW, REROUTE, CONTINUE = "STOP", "SLOW", "REROUTE", "CONTINUE"
COMMANDS = (STOP, SLOW, REROUTE, CONTINUE)
PROGRESS = {CONTINUE: 1.0, SLOW: 0.6, REROUTE: 0.3, STOP: 0.0}

VEHICLE_RISK = 0.5
TTC_STOP_S = 3.0
PED_RISK = 0.2
PED_STOP_M = 2.0
BLOCKED = 0.5

AISLE = "aisle_blocked"


class _NodeLike(Protocol):
    @property
    def id(self) -> str: ...
    @property
    def value(self) -> object: ...


@dataclass(frozen=True, slots=True)
class TreeSpec:
    id: str
    label: str
    test: str | None = None
    command: str | None = None


TREE: tuple[TreeSpec, ...] = (
    TreeSpec("root", "vehicle on a collision course?", f"vehicle collision_risk >= {VEHICLE_RISK}"),
    TreeSpec("vehicle_close", "too close to manoeuvre?", f"vehicle ttc < {TTC_STOP_S} s"),
    TreeSpec("stop_vehicle", "STOP", command=STOP),
    TreeSpec("reroute_vehicle", "REROUTE", command=REROUTE),
    TreeSpec("ped_in_path", "pedestrian in path?", f"pedestrian collision_risk >= {PED_RISK}"),
    TreeSpec("ped_close", "d_ped < 2 m?", f"pedestrian distance < {PED_STOP_M} m"),
    TreeSpec("stop_ped", "STOP", command=STOP),
    TreeSpec("slow", "SLOW", command=SLOW),
    TreeSpec("path_clear", "path clear?", f"aisle_blocked < {BLOCKED}"),
    TreeSpec("continue", "CONTINUE", command=CONTINUE),
    TreeSpec("reroute_path", "REROUTE", command=REROUTE),
)
TREE_EDGES: tuple[tuple[str, str, str], ...] = (
    ("root", "vehicle_close", "yes"),
    ("root", "ped_in_path", "no"),
    ("vehicle_close", "stop_vehicle", "yes"),
    ("vehicle_close", "reroute_vehicle", "no"),
    ("ped_in_path", "ped_close", "yes"),
    ("ped_in_path", "path_clear", "no"),
    ("ped_close", "stop_ped", "yes"),
    ("ped_close", "slow", "no"),
    ("path_clear", "continue", "yes"),
    ("path_clear", "reroute_path", "no"),
)
_PARENT = {child: parent for parent, child, _ in TREE_EDGES}
_BRANCH = {child: label for _, child, label in TREE_EDGES}


def leaf_path(leaf: str) -> tuple[str, ...]:
    """Node ids from the root to ``leaf``."""
    path = [leaf]
    while path[-1] in _PARENT:
        path.append(_PARENT[path[-1]])
    return tuple(reversed(path))


LEAVES = {spec.id: spec.command for spec in TREE if spec.command is not None}
LEAF_PATHS = {leaf: leaf_path(leaf) for leaf in LEAVES}
TESTS = {spec.id: spec for spec in TREE}


@dataclass(frozen=True, slots=True)
class PolicyInput:
    """Which belief nodes the policy reads: pedestrians, vehicles and the aisle state."""

    peds: tuple[tuple[str, str, str], ...] = ()
    """(entity, collision_risk node, distance node) per pedestrian."""
    vehicles: tuple[tuple[str, str, str], ...] = ()
    """(entity, collision_risk node, ttc node) per vehicle."""
    aisle: str = AISLE

    @classmethod
    def from_nodes(cls, nodes: Iterable[_NodeLike]) -> PolicyInput:
        """Read the structure off a belief graph (live, or decoded from a log)."""
        ids = {n.id: n.value for n in nodes}
        peds, vehicles = [], []
        for nid, value in ids.items():
            if "." in nid:
                continue
            risk = f"{nid}.collision_risk"
            if value == "person" and risk in ids and f"{nid}.distance" in ids:
                peds.append((nid, risk, f"{nid}.distance"))
            elif value == "forklift" and risk in ids and f"{nid}.ttc" in ids:
                vehicles.append((nid, risk, f"{nid}.ttc"))
        return cls(tuple(peds), tuple(vehicles))


@dataclass(frozen=True, slots=True)
class Outcome:
    command: str
    path: tuple[str, ...]
    tests: tuple[tuple[str, str | None], ...]
    """(tree node, belief node it tested) for each test on the taken path."""


def evaluate(inp: PolicyInput, v: Mapping[str, object]) -> Outcome:
    """Run the tree on node values ``v``; return the command, the path and what was tested."""
    veh: tuple[str, str, str] | None = None
    best = -1.0
    for item in inp.vehicles:
        r = float(v[item[1]])  # type: ignore[arg-type]
        if r > best:
            best, veh = r, item
    tests: tuple[tuple[str, str | None], ...]
    if veh is not None and best >= VEHICLE_RISK:
        tests = (("root", veh[1]), ("vehicle_close", veh[2]))
        if float(v[veh[2]]) < TTC_STOP_S:  # type: ignore[arg-type]
            return Outcome(STOP, LEAF_PATHS["stop_vehicle"], tests)
        return Outcome(REROUTE, LEAF_PATHS["reroute_vehicle"], tests)
    root = ("root", veh[1] if veh is not None else None)

    nearest: tuple[str, str, str] | None = None
    nearest_d = 0.0
    top: tuple[str, str, str] | None = None
    top_r = -1.0
    for item in inp.peds:
        r = float(v[item[1]])  # type: ignore[arg-type]
        if r > top_r:
            top_r, top = r, item
        if r >= PED_RISK:
            d = float(v[item[2]])  # type: ignore[arg-type]
            if nearest is None or d < nearest_d:
                nearest, nearest_d = item, d
    if nearest is not None:
        tests = (root, ("ped_in_path", nearest[1]), ("ped_close", nearest[2]))
        if nearest_d < PED_STOP_M:
            return Outcome(STOP, LEAF_PATHS["stop_ped"], tests)
        return Outcome(SLOW, LEAF_PATHS["slow"], tests)
    tests = (root, ("ped_in_path", top[1] if top is not None else None), ("path_clear", inp.aisle))
    if float(v[inp.aisle]) < BLOCKED:  # type: ignore[arg-type]
        return Outcome(CONTINUE, LEAF_PATHS["continue"], tests)
    return Outcome(REROUTE, LEAF_PATHS["reroute_path"], tests)


def choose(inp: PolicyInput, v: Mapping[str, Any]) -> str:
    """The command alone: ``evaluate(inp, v).command`` without the bookkeeping.

    The prober calls this thousands of times per second; a test pins it to ``evaluate``.
    """
    veh_risk, veh_ttc = -1.0, ""
    for _, risk, ttc in inp.vehicles:
        r = v[risk]
        if r > veh_risk:
            veh_risk, veh_ttc = r, ttc
    if veh_risk >= VEHICLE_RISK:
        return STOP if v[veh_ttc] < TTC_STOP_S else REROUTE
    nearest = -1.0
    for _, risk, dist in inp.peds:
        if v[risk] >= PED_RISK:
            d = v[dist]
            if nearest < 0.0 or d < nearest:
                nearest = d
    if nearest >= 0.0:
        return STOP if nearest < PED_STOP_M else SLOW
    return CONTINUE if v[inp.aisle] < BLOCKED else REROUTE


def factors_of(outcome: Outcome) -> list[str]:
    """The belief nodes the decision depended on, in tree order, without repeats."""
    seen: list[str] = []
    for _, node in outcome.tests:
        if node is not None and node not in seen:
            seen.append(node)
    return seen


# --- alternatives ----------------------------------------------------------------------

_THRESHOLD = {
    "root": VEHICLE_RISK,
    "vehicle_close": TTC_STOP_S,
    "ped_in_path": PED_RISK,
    "ped_close": PED_STOP_M,
    "path_clear": BLOCKED,
}


def _why(test: str, node: str | None, v: Mapping[str, object], branch: str) -> str:
    if node is None:
        return {
            "root": "no vehicle detected",
            "ped_in_path": "no pedestrian detected",
        }.get(test, f"{test}: {branch}")
    value = v[node]
    t = _THRESHOLD[test]
    shown = f"{value:.2f}" if isinstance(value, float) else str(value)
    if test == "root":
        op = ">=" if branch == "yes" else "<"
        return (
            f"vehicle on a collision course ({node} {shown} {op} {t:.2f})"
            if branch == "yes"
            else f"no vehicle on a collision course ({node} {shown} {op} {t:.2f})"
        )
    if test == "vehicle_close":
        return (
            f"vehicle too close to manoeuvre ({node} {shown} s < {t:.1f} s)"
            if branch == "yes"
            else f"vehicle far enough to avoid ({node} {shown} s >= {t:.1f} s)"
        )
    if test == "ped_in_path":
        return (
            f"pedestrian in path ({node} {shown} >= {t:.2f})"
            if branch == "yes"
            else f"no pedestrian in path ({node} {shown} < {t:.2f})"
        )
    if test == "ped_close":
        return (
            f"pedestrian inside stop distance ({node} {shown} m < {t:.1f} m)"
            if branch == "yes"
            else f"pedestrian beyond stop distance ({node} {shown} m >= {t:.1f} m)"
        )
    return (
        f"path clear ({node} {shown} < {t:.2f})"
        if branch == "yes"
        else f"aisle blocked ({node} {shown} >= {t:.2f})"
    )


def _margin(test: str, node: str | None, v: Mapping[str, object]) -> float:
    if node is None:
        return 1.0
    value = v[node]
    if not isinstance(value, (int, float)):
        return 1.0
    t = _THRESHOLD[test]
    return min(1.0, abs(float(value) - t) / max(abs(t), 1e-9))


@dataclass(slots=True)  # not frozen: ~4x cheaper to create
class Scored:
    command: str
    score: float
    rejected_because: str


def score_alternatives(outcome: Outcome, v: Mapping[str, object]) -> tuple[float, list[Scored]]:
    """Score the chosen command and every alternative; say why each alternative lost.

    score = progress(command) - penalty. An alternative is penalised 1.01 + margin at the
    first test on the taken path that rules its nearest leaf out (margin = how far past the
    threshold the tested value was, relative, capped at 1), so the chosen command always
    scores highest. The stated reason is that test and the value that decided it.
    """
    tested = dict(outcome.tests)
    out: list[Scored] = []
    for cmd, split, branch in _SPLITS[outcome.path]:
        node = tested.get(split)
        reason = _why(split, node, v, branch)
        penalty = 1.01 + _margin(split, node, v)
        out.append(Scored(cmd, round(PROGRESS[cmd] - penalty, 3), reason))
    return PROGRESS[outcome.command], out


def _splits(taken: tuple[str, ...]) -> list[tuple[str, str, str]]:
    """(alternative, test where the taken path leaves its nearest leaf, branch taken there)."""
    chosen = LEAVES[taken[-1]]
    out = []
    for cmd in COMMANDS:
        if cmd == chosen:
            continue
        best: tuple[int, str] | None = None
        for leaf, c in LEAVES.items():
            if c != cmd:
                continue
            path = LEAF_PATHS[leaf]
            k = 0
            while k < min(len(path), len(taken)) and path[k] == taken[k]:
                k += 1
            if best is None or k > best[0]:
                best = (k, leaf)
        assert best is not None
        out.append((cmd, taken[best[0] - 1], _BRANCH[taken[best[0]]]))
    return out


_SPLITS = {path: _splits(path) for path in LEAF_PATHS.values()}
"""Per taken path: where each alternative was ruled out (the tree is fixed)."""


def describe(outcome: Outcome, v: Mapping[str, object]) -> list[str]:
    """One phrase per test on the taken path, for the rationale text."""
    phrases = []
    for (test, node), nxt in zip(outcome.tests, outcome.path[1:], strict=False):
        phrases.append(_why(test, node, v, _BRANCH[nxt]))
    return phrases
