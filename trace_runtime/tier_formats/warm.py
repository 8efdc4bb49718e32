"""The warm tier: flagged cycles in full, routine cycles as summaries. Lossy by design.

A cycle is *flagged* when something in it deserves a full record: an execution flag (other
than the informational ``scenario:*`` ones), a failed compliance check, a change of action
command, a gap (dropped cycles, a skipped cycle number, more than 1.5 periods of silence),
or a documentation gap (a layer or the seal missing, a truncated rationale, no
counterfactuals and no "none applicable", a factor that does not reach an entity with an
evidence ref). Flagged cycles and the cycles within ``context_ns`` of each are copied byte for
byte.

Every other cycle keeps its seal in full (so the hash chain of seals still verifies) and a
summary on ``/trace/summary``: the layer messages pruned to what explains the decision,
with the same field names as the full JSON (see ``summarize``). Sensor readings of summary
cycles are dropped unless ``keep_readings`` is set, so on those cycles the causal chain ends
at the evidence ref (ET_partial stays computable; the reading itself is gone).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import orjson

from trace_runtime.encoding.cycles import Cycle, RawMessage
from trace_runtime.flags import SCENARIO_FLAG
from trace_runtime.recording_records import TOPIC_RECORDING
from trace_runtime.records import (
    LAYER_TOPICS,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_CHECKPOINT,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)

SUMMARY_TOPIC = "/trace/summary"

_KEPT_WHOLE = (TOPIC_CHECKPOINT, TOPIC_RECORDING)
"""What a summarised cycle keeps of its messages besides its seal, byte for byte."""
SUMMARY_SCHEMA = (
    "trace.Summary",
    "jsonschema",
    b'{"type":"object","title":"Warm-tier summary of one routine cycle",'
    b'"description":"layers: layer topic -> that layer message pruned; same field names",'
    b'"required":["cycle","t_ns","layers"],"properties":{"cycle":{"type":"integer"},'
    b'"t_ns":{"type":"integer"},"layers":{"type":"object"}}}',
)
DEFAULT_CONTEXT_NS = 2_000_000_000
_MAX_PENDING = 100_000  # bounds memory if log times ever run backwards
INFORMATIONAL_PREFIXES = (SCENARIO_FLAG,)


@dataclass(frozen=True, slots=True)
class WarmPolicy:
    """What the warm tier keeps in full."""

    context_ns: int = DEFAULT_CONTEXT_NS
    """Log time (ns) of cycles kept in full before and after each flagged cycle."""
    keep_readings: bool = False
    """Keep the sensor readings that a summary's evidence refs point at (same cycle)."""
    informational_prefixes: tuple[str, ...] = INFORMATIONAL_PREFIXES
    """Execution flags with these prefixes do not flag a cycle."""

    def to_metadata(self) -> dict[str, str]:
        """The policy as a warm segment's ``trace.tier`` record states it (context in seconds)."""
        return {
            "context_s": repr(self.context_ns / 1e9),
            "keep_readings": str(self.keep_readings).lower(),
            "informational_prefixes": ",".join(self.informational_prefixes),
        }

    @classmethod
    def from_metadata(cls, data: dict[str, str]) -> WarmPolicy:
        """The policy a warm segment's ``trace.tier`` record states."""
        prefixes = data.get("informational_prefixes", ",".join(INFORMATIONAL_PREFIXES))
        return cls(
            context_ns=_seconds_as_ns(data.get("context_s")),
            keep_readings=data.get("keep_readings", "false") == "true",
            informational_prefixes=tuple(p for p in prefixes.split(",") if p),
        )


def _seconds_as_ns(text: str | None) -> int:
    """The ``context_s`` field of a policy record (seconds, as ``repr`` writes a float) in ns."""
    return DEFAULT_CONTEXT_NS if text is None else round(float(text) * 1e9)


# --- cycles as message groups ----------------------------------------------------------


def iter_message_cycles(messages: Iterable[RawMessage]) -> Iterator[list[RawMessage]]:
    """The messages of each cycle, in file order: everything up to and including a seal."""
    group: list[RawMessage] = []
    for msg in messages:
        group.append(msg)
        if msg.topic == TOPIC_SEAL:
            yield group
            group = []
    if group:
        yield group


@dataclass(slots=True)
class _Parsed:
    messages: list[RawMessage]
    layers: dict[str, Any]
    seal: dict[str, Any] | None
    number: int
    t_ns: int


def _parse(group: list[RawMessage]) -> _Parsed:
    layers: dict[str, Any] = {}
    seal: dict[str, Any] | None = None
    for msg in group:
        if msg.topic in LAYER_TOPICS or msg.topic == TOPIC_SEAL:
            try:
                value = orjson.loads(msg.data)
            except orjson.JSONDecodeError:
                value = None
            if msg.topic == TOPIC_SEAL:
                seal = value if isinstance(value, dict) else None
            elif isinstance(value, dict):
                layers[msg.topic] = value
    last = group[-1]
    if last.topic == TOPIC_SEAL:
        number, t_ns = last.sequence, last.log_time_ns
    else:
        first: dict[str, Any] = next(iter(layers.values()), {})
        number = int(first.get("cycle", -1)) if isinstance(first.get("cycle"), int) else -1
        t_ns = max(m.log_time_ns for m in group)
    return _Parsed(group, layers, seal, number, t_ns)


class _Flagger:
    """Why a cycle must be kept in full; remembers the previous cycle for changes and gaps."""

    def __init__(self, policy: WarmPolicy, period_ns: int) -> None:
        self._policy = policy
        self._period_ns = period_ns
        self._command: str | None = None
        self._number: int | None = None
        self._t_ns: int | None = None

    def reasons(self, cycle: _Parsed) -> list[str]:
        out: list[str] = []
        action = cycle.layers.get(TOPIC_ACTION)
        execution = cycle.layers.get(TOPIC_EXECUTION)
        if isinstance(execution, dict):
            for flag in _list(execution.get("flags")):
                if isinstance(flag, str) and not flag.startswith(
                    self._policy.informational_prefixes
                ):
                    out.append(f"flag:{flag}")
            for check in _dicts(execution.get("checks")):
                if check.get("passed") is False:
                    out.append(f"check:{check.get('rule', '?')}")
        command = action.get("command") if isinstance(action, dict) else None
        if isinstance(command, str):
            if self._command is not None and command != self._command:
                out.append(f"command:{self._command}->{command}")
            self._command = command
        if cycle.seal is None:
            out.append("unsealed")
        elif isinstance(cycle.seal.get("dropped"), int) and cycle.seal["dropped"] > 0:
            out.append(f"gap:dropped={cycle.seal['dropped']}")
        if self._number is not None and cycle.number > self._number + 1:
            out.append(f"gap:cycles {self._number + 1}..{cycle.number - 1} missing")
        if (
            self._t_ns is not None
            and self._period_ns > 0
            and 2 * (cycle.t_ns - self._t_ns) > 3 * self._period_ns
        ):
            out.append("gap:time")
        self._number, self._t_ns = cycle.number, cycle.t_ns
        out += _documentation_gaps(cycle.layers)
        return out


def _documentation_gaps(layers: dict[str, Any]) -> list[str]:
    missing = [t.rsplit("/", 1)[-1] for t in LAYER_TOPICS if t not in layers]
    if missing:
        return [f"missing:{','.join(missing)}"]
    out: list[str] = []
    action = layers[TOPIC_ACTION]
    rationale = action.get("rationale") if isinstance(action.get("rationale"), dict) else {}
    if rationale.get("truncated") is True:
        out.append("rationale:truncated")
    factors = list(_dicts(rationale.get("factors")))
    if not factors:
        out.append("rationale:no-factors")
    if (
        not _list(action.get("counterfactuals"))
        and action.get("counterfactuals_none_applicable") is not True
    ):
        out.append("counterfactuals:missing")
    graph = _Graph(layers[TOPIC_BELIEF])
    entities = {e.get("id"): e for e in _dicts(layers[TOPIC_PERCEPTION].get("entities"))}
    for factor in factors:
        node = factor.get("node")
        if not isinstance(node, str) or node not in graph.nodes:
            out.append(f"untraced:{node}")
            continue
        reached = [
            graph.nodes[n].get("entity")
            for n in graph.ancestors([node])
            if graph.nodes[n].get("kind") == "entity"
        ]
        if not any(
            any(
                isinstance(ev.get("ref"), dict)
                for ev in _dicts(entities.get(e, {}).get("evidence"))
            )
            for e in reached
        ):
            out.append(f"untraced:{node}")
    return out


# --- summaries ---------------------------------------------------------------------------


class _Graph:
    def __init__(self, belief: Any) -> None:
        self.nodes: dict[str, dict[str, Any]] = {}
        self.edges: list[dict[str, Any]] = []
        self.parents: dict[str, list[str]] = {}
        if not isinstance(belief, dict):
            return
        for node in _dicts(belief.get("nodes")):
            if isinstance(node.get("id"), str):
                self.nodes[node["id"]] = node
        for edge in _dicts(belief.get("edges")):
            self.edges.append(edge)
            parent, child = edge.get("parent"), edge.get("child")
            if isinstance(parent, str) and isinstance(child, str):
                self.parents.setdefault(child, []).append(parent)

    def ancestors(self, start: Iterable[str]) -> set[str]:
        """``start`` and every node reachable from it through parent edges."""
        seen: set[str] = set()
        stack = [s for s in start if isinstance(s, str)]
        while stack:
            node = stack.pop()
            if node in seen:
                continue
            seen.add(node)
            stack.extend(self.parents.get(node, ()))
        return seen


def _stamp(message: dict[str, Any]) -> dict[str, Any]:
    return {k: message[k] for k in ("cycle", "t_ns") if k in message}


def _pick(source: dict[str, Any], keys: Sequence[str]) -> dict[str, Any]:
    return {k: source[k] for k in keys if k in source}


def summarize(layers: dict[str, Any]) -> dict[str, Any]:
    """The warm summary of one cycle's layer messages (plain JSON dicts), keyed by topic.

    action: command, parameters, score, alternatives (command, score), rationale (text,
    factors with values, truncated), counterfactuals and counterfactuals_none_applicable;
    belief: the factor nodes and all their ancestors, with the edges among them; perception:
    the entities those nodes name (id, class, pose, confidence, evidence: sensor, weight,
    ref) and the sensors used / unavailable; execution: the whole record, every field a
    profile defines (planar motion, actuator channels with their units, deviation and its
    unit, checks, flags) and any a later profile adds: it is what "executed how" is read
    from, and small beside the other layers.
    """
    out: dict[str, Any] = {}
    action = layers.get(TOPIC_ACTION)
    factor_nodes: list[str] = []
    if isinstance(action, dict):
        out[TOPIC_ACTION], factor_nodes = _summarize_action(action)
    belief = layers.get(TOPIC_BELIEF)
    entity_ids: set[str] = set()
    if isinstance(belief, dict):
        out[TOPIC_BELIEF], entity_ids = _summarize_belief(belief, factor_nodes)
    perception = layers.get(TOPIC_PERCEPTION)
    if isinstance(perception, dict):
        out[TOPIC_PERCEPTION] = _summarize_perception(perception, entity_ids)
    execution = layers.get(TOPIC_EXECUTION)
    if isinstance(execution, dict):
        out[TOPIC_EXECUTION] = execution
    return out


def _summarize_action(action: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """The action's summary, and the belief nodes its rationale's factors name."""
    summary = _stamp(action)
    summary.update(_pick(action, ("command", "parameters", "score")))
    if "alternatives" in action:
        summary["alternatives"] = [
            _pick(a, ("command", "score")) for a in _dicts(action["alternatives"])
        ]
    factor_nodes: list[str] = []
    rationale = action.get("rationale")
    if isinstance(rationale, dict):
        summary["rationale"] = _pick(rationale, ("text", "factors", "truncated"))
        factor_nodes = [
            f["node"] for f in _dicts(rationale.get("factors")) if isinstance(f.get("node"), str)
        ]
    summary.update(_pick(action, ("counterfactuals", "counterfactuals_none_applicable")))
    return summary, factor_nodes


def _summarize_belief(
    belief: dict[str, Any], factor_nodes: list[str]
) -> tuple[dict[str, Any], set[str]]:
    """The belief graph cut to the factor nodes and their ancestors, and the entities named."""
    graph = _Graph(belief)
    keep = graph.ancestors(factor_nodes)
    nodes = [n for n in _dicts(belief.get("nodes")) if n.get("id") in keep]
    edges = [e for e in graph.edges if e.get("child") in keep and e.get("parent") in keep]
    entity_ids = {
        n["entity"] for n in nodes if n.get("kind") == "entity" and isinstance(n.get("entity"), str)
    }
    return {**_stamp(belief), "nodes": nodes, "edges": edges}, entity_ids


def _summarize_perception(perception: dict[str, Any], entity_ids: set[str]) -> dict[str, Any]:
    """The perceived entities the belief summary names, with their evidence."""
    entities = []
    for entity in _dicts(perception.get("entities")):
        if entity.get("id") not in entity_ids:
            continue
        kept = _pick(entity, ("id", "class", "pose", "confidence"))
        kept["evidence"] = [
            _pick(ev, ("sensor", "weight", "ref")) for ev in _dicts(entity.get("evidence"))
        ]
        entities.append(kept)
    return {
        **_stamp(perception),
        "entities": entities,
        **_pick(perception, ("sensors_used", "sensors_unavailable", "robot_pose")),
    }


def _referenced_readings(summary: dict[str, Any], sensors: list[RawMessage]) -> list[RawMessage]:
    wanted: set[tuple[Any, Any]] = set()
    perception = summary.get(TOPIC_PERCEPTION)
    if isinstance(perception, dict):
        for entity in _dicts(perception.get("entities")):
            for ev in _dicts(entity.get("evidence")):
                ref = ev.get("ref")
                if isinstance(ref, dict):
                    wanted.add((ref.get("topic"), ref.get("log_time_ns")))
    return [m for m in sensors if (m.topic, m.log_time_ns) in wanted]


# --- the warm stream ---------------------------------------------------------------------


@dataclass(slots=True)
class WarmCycle:
    """One cycle as the warm tier writes it."""

    number: int
    t_ns: int
    full: bool
    reasons: list[str]
    messages: list[RawMessage]


def warm_cycles(
    messages: Iterable[RawMessage], policy: WarmPolicy, period_ns: int
) -> Iterator[WarmCycle]:
    """Turn a hot message stream into the warm tier's cycles, in order.

    The context window is in log time: every cycle within ``context_ns`` of a flagged cycle
    (before or after) is kept in full, however many cycles that is around a gap. Memory is
    bounded by the cycles of one window. Deterministic: the same input and policy give the
    same output, which is how a warm segment is verified against its source.
    """
    window_ns = policy.context_ns
    flagger = _Flagger(policy, period_ns)
    pending: deque[list[Any]] = deque()  # [cycle, reasons, full], oldest first
    keep_until_ns: int | None = None
    for group in iter_message_cycles(messages):
        cycle = _parse(group)
        if cycle.seal is None and not cycle.layers:
            # No cycle here (e.g. the closing checkpoint after the last seal): copy it as is.
            pending.append([cycle, [], True])
            continue
        reasons = flagger.reasons(cycle)
        if reasons:
            for held in pending:
                if held[0].t_ns >= cycle.t_ns - window_ns:
                    held[2] = True
            keep_until_ns = cycle.t_ns + window_ns
        full = bool(reasons) or (keep_until_ns is not None and cycle.t_ns <= keep_until_ns)
        pending.append([cycle, reasons, full])
        # Cycles more than one window older than this one cannot be reached by a later flag.
        while pending and (
            pending[0][0].t_ns < cycle.t_ns - window_ns or len(pending) > _MAX_PENDING
        ):
            yield _emit(*_unpack(pending.popleft()), policy)
    while pending:
        yield _emit(*_unpack(pending.popleft()), policy)


def _unpack(held: list[Any]) -> tuple[_Parsed, list[str], bool]:
    return held[0], held[1], held[2]


def _emit(cycle: _Parsed, reasons: list[str], full: bool, policy: WarmPolicy) -> WarmCycle:
    if full or cycle.seal is None:
        return WarmCycle(cycle.number, cycle.t_ns, True, reasons, cycle.messages)
    seal_msg = cycle.messages[-1]
    summary = summarize(cycle.layers)
    # Signed checkpoints vouch for the chain of seals, which the warm tier keeps whole; the
    # windows of the robot's recordings stay whole too, so the recordings stay checkable.
    out = [m for m in cycle.messages if m.topic in _KEPT_WHOLE]
    if policy.keep_readings:
        sensors = [m for m in cycle.messages if not m.topic.startswith("/trace/")]
        out += _referenced_readings(summary, sensors)
    body = {"cycle": cycle.number, "t_ns": cycle.t_ns, "layers": summary}
    out.append(
        RawMessage(SUMMARY_TOPIC, seal_msg.sequence, seal_msg.log_time_ns, orjson.dumps(body))
    )
    out.append(seal_msg)
    return WarmCycle(cycle.number, cycle.t_ns, False, reasons, out)


# --- reading -----------------------------------------------------------------------------


def assemble_warm(messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
    """The reader's assembler for warm chunks: full cycles as in hot, summaries as summaries."""
    cycles: list[Cycle] = []
    payloads: dict[str, bytes] = {}
    sensors: list[RawMessage] = []
    summary: dict[str, Any] | None = None
    for msg in messages:
        if msg.topic == TOPIC_CHECKPOINT:
            continue  # a chain-head anchor, not part of any cycle (as in the hot tier)
        if msg.topic == SUMMARY_TOPIC:
            body = orjson.loads(msg.data)
            layers = body.get("layers") if isinstance(body, dict) else None
            summary = layers if isinstance(layers, dict) else {}
        elif msg.topic.startswith("/trace/"):
            payloads[msg.topic] = msg.data
            if msg.topic == TOPIC_SEAL:
                cycles.append(
                    Cycle(msg.sequence, msg.log_time_ns, payloads, sensors, segment, summary)
                )
                payloads, sensors, summary = {}, [], None
        else:
            sensors.append(msg)
    if payloads or summary is not None:
        first = next(iter(payloads.values()), b"{}")
        parsed = orjson.loads(first)
        number = parsed.get("cycle", -1) if isinstance(parsed, dict) else -1
        t_ns = max((m.log_time_ns for m in messages), default=0)
        cycles.append(Cycle(int(number), t_ns, payloads, sensors, segment, summary))
    return cycles


class WarmAssembler:
    """The reader's assembler for the warm tier: like hot, a cycle run ends with its seal."""

    closer_topic = TOPIC_SEAL

    def __call__(self, messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
        return assemble_warm(messages, segment)


def _list(value: Any) -> list[Any]:
    return value if isinstance(value, list) else []


def _dicts(value: Any) -> Iterator[dict[str, Any]]:
    if isinstance(value, list):
        for item in value:
            if isinstance(item, dict):
                yield item
