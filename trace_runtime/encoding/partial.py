"""Partial decoding: a layer message read for one use, only the fields that use reads.

A full parse (``Cycle.layer``: orjson into dicts) builds every object of a record; metrics
read a handful of keys of three layers, and an action's decision tree alone is a third of
its bytes. Here each use names the fields it reads as a *shape* (msgspec types), and
``msgspec`` decodes those straight from the stored bytes, skipping the rest without building
it. The rules that read the layers (the ET walk, DR, the seal check's evidence step) read
plain JSON, so the metrics shapes are ``TypedDict``s: msgspec gives real ``dict``s holding
only the declared keys, and every rule reads them unchanged (one walker, one seal check).
A use whose reader is written for the shape (``DecisionFields``) takes a ``Struct``.

What a shape gives is the full parse restricted to its keys, or nothing:

- each declared field's type is every type a valid record gives it (and JSON's ``null``
  where the model allows it); a value of any other type is refused, never coerced;
- integers are bounded to int64 (orjson reads a larger literal as a float, where msgspec
  would give the exact big integer);
- no float field is declared (msgspec reads ``1`` into a float field as ``1.0``);
- bytes orjson refuses must be refused too: msgspec checks the syntax of what it skips but
  not its UTF-8 (so a message that is not ASCII is decoded as UTF-8 first) nor a skipped
  number's range (orjson refuses ``1e400``; see ``docs/performance.md``, "Partial decoding",
  for the one case left);
- anything refused (``None`` from ``decode``) is read by the full parse, so errors and odd
  records come out exactly as before (``read_layer``).

Digests are never taken here: the seal check hashes the stored bytes themselves.
``tests/trace_runtime/encoding/test_partial.py`` pins every shape to the full parse over random
valid records, and over damaged bytes.
"""

from __future__ import annotations

from typing import Annotated, Any, Generic, TypedDict, TypeVar

import msgspec

from trace_runtime.encoding.cycles import Cycle, parse_json
from trace_runtime.records import (
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)

__all__ = [
    "DECISION_FIELDS",
    "INDEX_ACTION",
    "INDEX_BELIEF",
    "INDEX_PERCEPTION",
    "METRICS_ACTION",
    "METRICS_BELIEF",
    "METRICS_PERCEPTION",
    "RULES_ACTION",
    "RULES_BELIEF",
    "RULES_EXECUTION",
    "RULES_PERCEPTION",
    "SEAL_FIELDS",
    "DecisionFields",
    "FactorFields",
    "SealFields",
    "Shape",
    "decision_fields",
    "read_layer",
]

T = TypeVar("T")

Int = Annotated[int, msgspec.Meta(ge=-(2**63), le=2**63 - 1)]
"""An integer orjson reads as one: int64 (orjson reads up to uint64 as an int and a larger
literal as a float; msgspec bounds only within int64, so the rest takes the full parse)."""


class Shape(Generic[T]):
    """The fields one use reads of one layer, decoded straight from its stored bytes."""

    __slots__ = ("_decode", "name", "topic")

    def __init__(self, name: str, topic: str, shape: type[T]) -> None:
        self.name = name
        self.topic = topic
        self._decode = msgspec.json.Decoder(shape).decode

    def decode(self, data: bytes) -> T | None:
        """The shape's fields of ``data``; None when the fast path cannot vouch that they
        are the full parse's (then the caller reads the message in full)."""
        if not data.isascii():
            try:
                data.decode()  # orjson refuses what is not UTF-8; msgspec skips it unread
            except UnicodeDecodeError:
                return None
        try:
            return self._decode(data)
        except (msgspec.DecodeError, RecursionError):
            return None  # ValidationError is a DecodeError


def read_layer(cycle: Cycle, shape: Shape[Any]) -> Any:
    """The layer on ``shape.topic`` as the shape's fields, or, when the fast path declines,
    the full layer (``Cycle.layer``: the same JSON with every key, the warm summary's, or
    None when the cycle has no such message). A message orjson cannot parse raises
    ``PayloadError`` as ``Cycle.layer`` does."""
    data = cycle.payloads.get(shape.topic)
    if data is not None:
        found = shape.decode(data)
        if found is not None:
            return found
        return parse_json(data, shape.topic, cycle.segment)
    if cycle.summary is not None:
        return cycle.summary.get(shape.topic)
    return None


# --- metrics: what ET, DR and the seal check's evidence step read --------------------------


class _Skipped(TypedDict, total=False):
    """An object whose fields the use does not read (only that it is there)."""


class _FactorRef(TypedDict, total=False):
    node: str


class _Rationale(TypedDict, total=False):
    factors: list[_FactorRef]
    truncated: bool


class MetricsAction(TypedDict, total=False):
    """An action as DR (``metrics.decision.dr_problems``) and ET read it."""

    command: str
    alternatives: list[_Skipped]
    rationale: _Rationale
    counterfactuals: list[_Skipped]
    counterfactuals_none_applicable: bool


class _Node(TypedDict, total=False):
    id: str
    kind: str
    entity: str | None


class _Edge(TypedDict, total=False):
    parent: str
    child: str


class MetricsBelief(TypedDict, total=False):
    """A belief graph as the ET walk reads it: node ids, kinds and entities; edges."""

    nodes: list[_Node]
    edges: list[_Edge]


class _Ref(TypedDict, total=False):
    topic: str
    log_time_ns: Int
    sequence: Int | None
    digest: str | None
    recording: str | None


class _Evidence(TypedDict, total=False):
    ref: _Ref | None


class _Entity(TypedDict, total=False):
    id: str
    evidence: list[_Evidence]


class MetricsPerception(TypedDict, total=False):
    """A perception as the ET walk, the seal check's evidence step and the external
    recordings' tally read it: each entity's id and its evidence refs."""

    entities: list[_Entity]


METRICS_ACTION: Shape[MetricsAction] = Shape("metrics action", TOPIC_ACTION, MetricsAction)
METRICS_BELIEF: Shape[MetricsBelief] = Shape("metrics belief", TOPIC_BELIEF, MetricsBelief)
METRICS_PERCEPTION: Shape[MetricsPerception] = Shape(
    "metrics perception", TOPIC_PERCEPTION, MetricsPerception
)


# --- the seal check: a seal's own fields ----------------------------------------------------


class SensorCoverFields(msgspec.Struct, frozen=True, gc=False, forbid_unknown_fields=True):
    """A seal's ``sensors`` (profile 1.3): how many sensor readings the cycle logged and the
    digest over them (``trace_runtime.chain.sensor_cover``)."""

    count: Int
    digest: str


class SealFields(msgspec.Struct, frozen=True, gc=False, forbid_unknown_fields=True):
    """A seal as the seal check reads it (``seal_check``): every field a seal has, typed as
    the check requires (``cycle``, ``t_ns`` and ``dropped`` integers, ``digests`` strings
    keyed by strings, ``prev`` a string). A key the seal record does not have is refused
    rather than skipped, so nothing of a seal goes unread (a skipped ``1e400`` would pass
    here where orjson refuses the record); a refusal takes the full parse."""

    cycle: Int
    t_ns: Int
    digests: dict[str, str]
    prev: str
    dropped: Int = 0
    sensors: SensorCoverFields | None = None


SEAL_FIELDS: Shape[SealFields] = Shape("seal fields", TOPIC_SEAL, SealFields)


# --- rules: what the signals of ``trace-audit check`` read -----------------------------------

Number = int | float
"""A JSON number as orjson gives it: an int, or a float (never coerced to one)."""


class _RulesRef(TypedDict, total=False):
    topic: str
    log_time_ns: Int
    recording: str | None


class _RulesEvidence(TypedDict, total=False):
    sensor: str
    ref: _RulesRef | None


_RulesEntity = TypedDict(
    "_RulesEntity", {"id": str, "class": str, "evidence": list[_RulesEvidence]}, total=False
)


class RulesPerception(TypedDict, total=False):
    """Each perceived entity's id and class (``nearest.<class>``), the sensors the robot
    used and missed (``perception.*``) and each evidence item's sensor and ref
    (``evidence.age_s``)."""

    entities: list[_RulesEntity]
    sensors_used: list[str]
    sensors_unavailable: list[str]


class _RulesNode(TypedDict, total=False):
    id: str
    kind: str
    label: str
    unit: str | None
    value: Number | str | bool | None


class RulesBelief(TypedDict, total=False):
    """The distance nodes and the edges from entities to them (``nearest.<class>``)."""

    nodes: list[_RulesNode]
    edges: list[_Edge]


class _RulesFactor(TypedDict, total=False):
    node: str
    name: str
    value: Number | str | bool | None


class _RulesRationale(TypedDict, total=False):
    factors: list[_RulesFactor]


class RulesAction(TypedDict, total=False):
    """The command and the factors' values (``command.*``, ``factor.*``)."""

    command: str
    rationale: _RulesRationale


class _Motion(TypedDict, total=False):
    linear: Number


class _Check(TypedDict, total=False):
    rule: str
    passed: bool


class _Channel(TypedDict, total=False):
    name: str
    intended: Number | None
    actual: Number | None
    deviation: Number | None
    ref: _RulesRef | None


class RulesExecution(TypedDict, total=False):
    """The planar motion, the checks, the flags and the actuator channels
    (``channel.*``, ``check.*``, ``flag.*``; a channel's ref for ``evidence.age_s``)."""

    intended: _Motion | None
    actual: _Motion | None
    checks: list[_Check]
    flags: list[str]
    channels: list[_Channel]


RULES_PERCEPTION: Shape[RulesPerception] = Shape(
    "rules perception", TOPIC_PERCEPTION, RulesPerception
)
RULES_BELIEF: Shape[RulesBelief] = Shape("rules belief", TOPIC_BELIEF, RulesBelief)
RULES_ACTION: Shape[RulesAction] = Shape("rules action", TOPIC_ACTION, RulesAction)
RULES_EXECUTION: Shape[RulesExecution] = Shape("rules execution", TOPIC_EXECUTION, RulesExecution)

# --- the fleet index: what metrics read, and what the index's rows keep -----------------------


class _IndexFactor(TypedDict, total=False):
    node: str
    name: str
    value: Number | str | bool | None
    unit: str | None


class _IndexRationale(TypedDict, total=False):
    factors: list[_IndexFactor]
    truncated: bool


class IndexAction(TypedDict, total=False):
    """``MetricsAction`` and each factor's name, value and unit (``fleet.rows``)."""

    command: str
    alternatives: list[_Skipped]
    rationale: _IndexRationale
    counterfactuals: list[_Skipped]
    counterfactuals_none_applicable: bool


class _IndexNode(TypedDict, total=False):
    id: str
    kind: str
    entity: str | None
    label: str
    unit: str | None
    value: Number | str | bool | None


class IndexBelief(TypedDict, total=False):
    """``MetricsBelief`` and the distance nodes' labels, units and values."""

    nodes: list[_IndexNode]
    edges: list[_Edge]


class _IndexPose(TypedDict, total=False):
    position: list[Number]


_IndexEntity = TypedDict(
    "_IndexEntity",
    {
        "id": str,
        "class": str,
        "pose": _IndexPose,
        "confidence": dict[str, Number],
        "evidence": list[_Evidence],
    },
    total=False,
)


class IndexPerception(TypedDict, total=False):
    """``MetricsPerception`` and each entity's class, position and confidences."""

    entities: list[_IndexEntity]


INDEX_ACTION: Shape[IndexAction] = Shape("index action", TOPIC_ACTION, IndexAction)
INDEX_BELIEF: Shape[IndexBelief] = Shape("index belief", TOPIC_BELIEF, IndexBelief)
INDEX_PERCEPTION: Shape[IndexPerception] = Shape(
    "index perception", TOPIC_PERCEPTION, IndexPerception
)


# --- a decision's own fields, for the library's iteration -----------------------------------


class FactorFields(msgspec.Struct, frozen=True, gc=False):
    """A factor of a decision: its node, name, the value the policy saw and its unit."""

    node: str
    value: str | bool | int | float
    name: str = ""
    unit: str | None = None


class _RationaleFields(msgspec.Struct, frozen=True, gc=False):
    text: str
    factors: list[FactorFields] = []
    truncated: bool = False


class _Named(msgspec.Struct, frozen=True, gc=False):
    """A record counted, not read (an alternative, a counterfactual)."""


class DecisionFields(msgspec.Struct, frozen=True, gc=False):
    """What a decision chose and why, from its action message alone: the stamp, the command,
    its score, the rationale and its factors, and how many alternatives and counterfactuals
    were logged. Decoded without building the alternatives, counterfactuals or the tree.
    A valid action gives every field as the ``ActionMessage`` model has it; what is not
    read is not validated either (an alternative's score past a double's range, say, which
    the model refuses)."""

    cycle: int
    t_ns: int
    command: str
    rationale: _RationaleFields
    score: float | None = None
    alternatives: list[_Named] = []
    counterfactuals: list[_Named] = []
    counterfactuals_none_applicable: bool = False

    @property
    def factors(self) -> list[FactorFields]:
        return self.rationale.factors

    @property
    def truncated(self) -> bool:
        return self.rationale.truncated


DECISION_FIELDS: Shape[DecisionFields] = Shape("decision fields", TOPIC_ACTION, DecisionFields)


def decision_fields(cycle: Cycle) -> DecisionFields | None:
    """A cycle's ``DecisionFields`` from its action message (None without one).

    An action the fast path declines is validated by its model (``Cycle.action``, which
    raises ``PayloadError`` for one that is not a valid action) and its fields taken from
    it; a warm summary's pruned action gives what it kept, or None when that is not a
    whole set of decision fields."""
    data = cycle.payloads.get(TOPIC_ACTION)
    if data is not None:
        found = DECISION_FIELDS.decode(data)
        if found is not None:
            return found
        model = cycle.action
        assert model is not None
        return msgspec.convert(model.model_dump(mode="json"), DecisionFields)
    if cycle.summary is not None:
        kept = cycle.summary.get(TOPIC_ACTION)
        if isinstance(kept, dict):
            try:
                return msgspec.convert(kept, DecisionFields)
            except msgspec.ValidationError:
                return None
    return None
