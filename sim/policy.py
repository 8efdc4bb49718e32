"""Layer 3 policy: the paper's Fig. 2 decision tree, extended with a vehicle branch and the
speed limit near people that the compliance monitor enforces.

::

    root: vehicle on a collision course?  (max vehicle collision_risk >= 0.5)
      yes -> vehicle_close: ttc < 3.0 s?        yes -> STOP      no -> REROUTE
      no  -> ped_in_path: pedestrian in path? (max pedestrian collision_risk >= 0.2)
               yes -> ped_close: d_ped < 2.0 m?  yes -> STOP      no -> SLOW
               no  -> path_clear: aisle_blocked < 0.5?
                        yes -> person_near: nearest person < 4.0 m?  yes -> SLOW
                                                                       no -> CONTINUE
                        no  -> REROUTE

``person_near`` slows the robot before the monitor's 0.5 m/s limit within 3 m of a person
applies (from cruise the actuator needs about 0.5 s, i.e. up to a metre of closing).

Every threshold has a hysteresis band: once a test has sent the robot down its "act" branch
(the leaf taken in the previous cycle is below it), the value must cross back past a
``hold`` level to leave it, so a value hovering at a threshold does not flip the command
cycle by cycle. Which leaf was held is part of the input (``PolicyInput.held``, logged as the
previous cycle's taken path) and each test's text says when its hold level applied.

The policy is a pure function of belief node values and the held leaf, so it can be re-run
on a logged belief graph (``PolicyInput.from_nodes``) and probed with interventions.
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
PERSON_SLOW_M = 4.0

AISLE = "aisle_blocked"


@dataclass(frozen=True, slots=True)
class Threshold:
    """A decision threshold with hysteresis: ``hold`` applies while one of ``held_by`` (the
    leaves on the test's acting side) was taken in the previous cycle."""

    enter: float
    hold: float
    held_by: frozenset[str]


THRESHOLDS: dict[str, Threshold] = {
    "root": Threshold(VEHICLE_RISK, 0.4, frozenset({"stop_vehicle", "reroute_vehicle"})),
    "vehicle_close": Threshold(TTC_STOP_S, 3.5, frozenset({"stop_vehicle"})),
    "ped_in_path": Threshold(PED_RISK, 0.15, frozenset({"stop_ped", "slow"})),
    "ped_close": Threshold(PED_STOP_M, 2.3, frozenset({"stop_ped"})),
    "path_clear": Threshold(BLOCKED, 0.4, frozenset({"reroute_path"})),
    "person_near": Threshold(PERSON_SLOW_M, 4.5, frozenset({"slow_near", "slow", "stop_ped"})),
}


def limit(test: str, held: str | None) -> float:
    """The threshold of ``test`` given the leaf taken in the previous cycle."""
    spec = THRESHOLDS[test]
    return spec.hold if held in spec.held_by else spec.enter


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
    TreeSpec("person_near", "person within 4 m?", f"nearest person distance < {PERSON_SLOW_M} m"),
    TreeSpec("slow_near", "SLOW", command=SLOW),
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
    ("path_clear", "person_near", "yes"),
    ("path_clear", "reroute_path", "no"),
    ("person_near", "slow_near", "yes"),
    ("person_near", "continue", "no"),
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
    """Which belief nodes the policy reads (pedestrians, vehicles, the aisle state) and the
    leaf it took in the previous cycle (for hysteresis; None: no previous decision)."""

    peds: tuple[tuple[str, str, str], ...] = ()
    """(entity, collision_risk node, distance node) per pedestrian."""
    vehicles: tuple[tuple[str, str, str], ...] = ()
    """(entity, collision_risk node, ttc node) per vehicle."""
    aisle: str = AISLE
    held: str | None = None

    @classmethod
    def from_nodes(cls, nodes: Iterable[_NodeLike], held: str | None = None) -> PolicyInput:
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
        return cls(tuple(peds), tuple(vehicles), held=held if held in LEAVES else None)


@dataclass(frozen=True, slots=True)
class Outcome:
    command: str
    path: tuple[str, ...]
    tests: tuple[tuple[str, str | None], ...]
    """(tree node, belief node it tested) for each test on the taken path."""
    held: str | None = None
    """The previous cycle's leaf, which set the hysteresis of these tests."""


def _limits(held: str | None) -> tuple[float, ...]:
    return tuple(limit(t, held) for t in _ORDER)


_ORDER = ("root", "vehicle_close", "ped_in_path", "ped_close", "path_clear", "person_near")
_LIMITS = {held: _limits(held) for held in (None, *LEAVES)}
"""Per held leaf, the thresholds in ``_ORDER`` (the prober calls ``choose`` very often)."""


def evaluate(inp: PolicyInput, v: Mapping[str, object]) -> Outcome:
    """Run the tree on node values ``v``; return the command, the path and what was tested."""
    veh_t, ttc_t, ped_t, close_t, blocked_t, near_t = _LIMITS[inp.held]
    held = inp.held
    veh: tuple[str, str, str] | None = None
    best = -1.0
    for item in inp.vehicles:
        r = float(v[item[1]])  # type: ignore[arg-type]
        if r > best:
            best, veh = r, item
    tests: tuple[tuple[str, str | None], ...]
    if veh is not None and best >= veh_t:
        tests = (("root", veh[1]), ("vehicle_close", veh[2]))
        if float(v[veh[2]]) < ttc_t:  # type: ignore[arg-type]
            return Outcome(STOP, LEAF_PATHS["stop_vehicle"], tests, held)
        return Outcome(REROUTE, LEAF_PATHS["reroute_vehicle"], tests, held)
    root = ("root", veh[1] if veh is not None else None)

    nearest: tuple[str, str, str] | None = None
    nearest_d = 0.0
    top: tuple[str, str, str] | None = None
    top_r = -1.0
    closest: tuple[str, str, str] | None = None
    closest_d = 0.0
    for item in inp.peds:
        r = float(v[item[1]])  # type: ignore[arg-type]
        d = float(v[item[2]])  # type: ignore[arg-type]
        if r > top_r:
            top_r, top = r, item
        if closest is None or d < closest_d:
            closest, closest_d = item, d
        if r >= ped_t and (nearest is None or d < nearest_d):
            nearest, nearest_d = item, d
    near_node = closest[2] if closest is not None else None
    if nearest is not None:
        tests = (root, ("ped_in_path", nearest[1]), ("ped_close", nearest[2]))
        if nearest_d < close_t:
            return Outcome(STOP, LEAF_PATHS["stop_ped"], tests, held)
        return Outcome(SLOW, LEAF_PATHS["slow"], tests, held)
    in_path = ("ped_in_path", top[1] if top is not None else None)
    if float(v[inp.aisle]) >= blocked_t:  # type: ignore[arg-type]
        tests = (root, in_path, ("path_clear", inp.aisle))
        return Outcome(REROUTE, LEAF_PATHS["reroute_path"], tests, held)
    tests = (root, in_path, ("path_clear", inp.aisle), ("person_near", near_node))
    if near_node is not None and closest_d < near_t:
        return Outcome(SLOW, LEAF_PATHS["slow_near"], tests, held)
    return Outcome(CONTINUE, LEAF_PATHS["continue"], tests, held)


def choose(inp: PolicyInput, v: Mapping[str, Any]) -> str:
    """The command alone: ``evaluate(inp, v).command`` without the bookkeeping.

    The prober calls this thousands of times per second; a test pins it to ``evaluate``.
    """
    veh_t, ttc_t, ped_t, close_t, blocked_t, near_t = _LIMITS[inp.held]
    veh_risk, veh_ttc = -1.0, ""
    for _, risk, ttc in inp.vehicles:
        r = v[risk]
        if r > veh_risk:
            veh_risk, veh_ttc = r, ttc
    if veh_risk >= veh_t:
        return STOP if v[veh_ttc] < ttc_t else REROUTE
    nearest = -1.0
    closest = -1.0
    for _, risk, dist in inp.peds:
        d = v[dist]
        if closest < 0.0 or d < closest:
            closest = d
        if v[risk] >= ped_t and (nearest < 0.0 or d < nearest):
            nearest = d
    if nearest >= 0.0:
        return STOP if nearest < close_t else SLOW
    if v[inp.aisle] >= blocked_t:
        return REROUTE
    return SLOW if 0.0 <= closest < near_t else CONTINUE


def factors_of(outcome: Outcome, inp: PolicyInput | None = None) -> list[str]:
    """The belief nodes the decision depended on, in tree order, without repeats.

    With ``inp``, the aisle state is a factor even when the taken path did not test it: a
    counterfactual that moves a tested value (a pedestrian's risk below its threshold) sends
    the tree down the branch that reads it, so what it would then choose depends on it.
    """
    seen: list[str] = []
    for _, node in outcome.tests:
        if node is not None and node not in seen:
            seen.append(node)
    if inp is not None and inp.aisle not in seen:
        seen.append(inp.aisle)
    return seen


# --- alternatives ----------------------------------------------------------------------


def _held_note(test: str, held: str | None) -> str:
    """Say so when the hysteresis level, not the entry threshold, decided a test."""
    if held not in THRESHOLDS[test].held_by:
        return ""
    return f"; hysteresis: hold level, {LEAVES[held]} at {held} last cycle"


def _why(
    test: str, node: str | None, v: Mapping[str, object], branch: str, held: str | None = None
) -> str:
    if node is None:
        return {
            "root": "no vehicle detected",
            "ped_in_path": "no pedestrian detected",
            "person_near": "no person detected",
        }.get(test, f"{test}: {branch}")
    value = v[node]
    t = limit(test, held)
    note = _held_note(test, held)
    shown = f"{value:.2f}" if isinstance(value, float) else str(value)
    if test == "root":
        op = ">=" if branch == "yes" else "<"
        return (
            f"vehicle on a collision course ({node} {shown} {op} {t:.2f}{note})"
            if branch == "yes"
            else f"no vehicle on a collision course ({node} {shown} {op} {t:.2f}{note})"
        )
    if test == "vehicle_close":
        return (
            f"vehicle too close to manoeuvre ({node} {shown} s < {t:.1f} s{note})"
            if branch == "yes"
            else f"vehicle far enough to avoid ({node} {shown} s >= {t:.1f} s{note})"
        )
    if test == "ped_in_path":
        return (
            f"pedestrian in path ({node} {shown} >= {t:.2f}{note})"
            if branch == "yes"
            else f"no pedestrian in path ({node} {shown} < {t:.2f}{note})"
        )
    if test == "ped_close":
        return (
            f"pedestrian inside stop distance ({node} {shown} m < {t:.1f} m{note})"
            if branch == "yes"
            else f"pedestrian beyond stop distance ({node} {shown} m >= {t:.1f} m{note})"
        )
    if test == "person_near":
        return (
            f"person within the slow zone ({node} {shown} m < {t:.1f} m{note})"
            if branch == "yes"
            else f"no person within the slow zone ({node} {shown} m >= {t:.1f} m{note})"
        )
    return (
        f"path clear ({node} {shown} < {t:.2f}{note})"
        if branch == "yes"
        else f"aisle blocked ({node} {shown} >= {t:.2f}{note})"
    )


def _margin(test: str, node: str | None, v: Mapping[str, object], held: str | None) -> float:
    if node is None:
        return 1.0
    value = v[node]
    if not isinstance(value, (int, float)):
        return 1.0
    t = limit(test, held)
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
        reason = _why(split, node, v, branch, outcome.held)
        penalty = 1.01 + _margin(split, node, v, outcome.held)
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
        phrases.append(_why(test, node, v, _BRANCH[nxt], outcome.held))
    return phrases
