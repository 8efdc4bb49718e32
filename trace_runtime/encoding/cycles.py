"""What a TRACE log is made of once read: stored messages, decision cycles, and how the
messages of the hot tier group into cycles.

This is the middle layer of the reader: below it, ``mcap_file`` turns bytes into messages;
above it, ``reader`` (one segment) and ``logset`` (many segments, tiers, robots) build on
these values. Tier codecs (``tier_formats.warm``, ``tier_formats.cold``) assemble their own
cycles from the same values.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Protocol, TypeVar

import orjson
from pydantic import BaseModel, ValidationError

from trace_runtime.chain import digest
from trace_runtime.errors import PayloadError
from trace_runtime.records import (
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_CHECKPOINT,
    TOPIC_EXECUTION,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
    ActionMessage,
    BeliefMessage,
    ExecutionMessage,
    PerceptionMessage,
    Seal,
)

M = TypeVar("M", bound=BaseModel)

# --- values ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RawMessage:
    """A message as stored: topic, per-channel sequence, log time, data."""

    topic: str
    sequence: int
    log_time_ns: int
    data: bytes


# The slot setters of RawMessage, taken once. A frozen dataclass's __init__ sets each field
# through object.__setattr__ (about 0.9 us a message); the reader makes every message of a
# log, 8-10 a decision cycle, so it fills the slots directly instead (about a third of that).
_new_object = object.__new__
_set_topic, _set_sequence, _set_log_time, _set_data = (
    getattr(RawMessage, f.name).__set__ for f in fields(RawMessage)
)


def raw_message(topic: str, sequence: int, log_time_ns: int, data: bytes) -> RawMessage:
    """``RawMessage(topic, sequence, log_time_ns, data)``, built faster: the same value (equal,
    same hash, as frozen), for the reader's inner loop."""
    message = _new_object(RawMessage)
    _set_topic(message, topic)
    _set_sequence(message, sequence)
    _set_log_time(message, log_time_ns)
    _set_data(message, data)
    return message


@dataclass(slots=True)
class Cycle:
    """One decision cycle as logged: its layer messages, seal and sensor readings.

    ``payloads`` maps a /trace topic to its canonical bytes. A warm-tier summary cycle has
    only the payloads that tier kept in full (at least the seal) and ``summary``: the pruned
    layer messages keyed by topic, shaped like the full JSON with the same field names.
    ``layer(topic)`` gives either, so analysis code reads both kinds of cycle alike.
    """

    cycle: int
    t_ns: int
    payloads: dict[str, bytes] = field(default_factory=dict)
    sensors: list[RawMessage] = field(default_factory=list)
    segment: str = ""
    summary: dict[str, Any] | None = None

    @property
    def sealed(self) -> bool:
        return TOPIC_SEAL in self.payloads

    @property
    def is_summary(self) -> bool:
        return self.summary is not None

    def json(self, topic: str) -> Any:
        """The full message on ``topic`` parsed as plain JSON, or None if absent.

        Raises ``PayloadError`` when the stored bytes are not JSON (or nest deeper than the
        parser's 1024 levels): a file's content, never a bug to show as a traceback."""
        data = self.payloads.get(topic)
        return None if data is None else parse_json(data, topic, self.segment)

    def layer(self, topic: str) -> object:
        """The message on ``topic`` as JSON: the full one, else the warm summary's, else None."""
        data = self.payloads.get(topic)
        if data is not None:
            return parse_json(data, topic, self.segment)
        if self.summary is not None:
            return self.summary.get(topic)
        return None

    def _model(self, topic: str, model: type[M]) -> M | None:
        data = self.payloads.get(topic)
        if data is None:
            return None
        try:
            return model.model_validate_json(data)
        except ValidationError as err:
            first = err.errors()[0] if err.error_count() else {"msg": str(err)}
            raise PayloadError(
                self.segment, topic, f"not a valid {model.__name__}: {first['msg']}"
            ) from err

    @property
    def seal(self) -> Seal | None:
        return self._model(TOPIC_SEAL, Seal)

    @property
    def perception(self) -> PerceptionMessage | None:
        return self._model(TOPIC_PERCEPTION, PerceptionMessage)

    @property
    def belief(self) -> BeliefMessage | None:
        return self._model(TOPIC_BELIEF, BeliefMessage)

    @property
    def action(self) -> ActionMessage | None:
        return self._model(TOPIC_ACTION, ActionMessage)

    @property
    def execution(self) -> ExecutionMessage | None:
        return self._model(TOPIC_EXECUTION, ExecutionMessage)

    def digests(self) -> dict[str, str]:
        """SHA-256 of each layer payload present, keyed by topic (what a seal names)."""
        return {t: digest(d) for t, d in self.payloads.items() if t != TOPIC_SEAL}


class Assembler(Protocol):
    """Turns a run of messages (in file order) into cycles.

    The run ends with a closing message (``closer_topic``: a seal, or a cold block) unless
    it is the end of the segment, where what follows the last closer is an unfinished cycle.
    """

    @property
    def closer_topic(self) -> str: ...

    def __call__(self, messages: Sequence[RawMessage], segment: str) -> list[Cycle]: ...


# --- hot tier assembly ---------------------------------------------------------------------


def assemble_hot(messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
    """Group hot-tier messages into cycles: everything up to and including a seal.

    Messages after the last seal (a cycle the writer never sealed) become an unsealed cycle,
    numbered from their own ``cycle`` field, so nothing that was written is hidden.
    """
    cycles: list[Cycle] = []
    payloads: dict[str, bytes] = {}
    sensors: list[RawMessage] = []
    for msg in messages:
        topic = msg.topic
        if topic.startswith("/trace/"):
            if topic == TOPIC_CHECKPOINT:
                continue  # a chain-head anchor, not part of any cycle (tlog.checkpoints)
            payloads[topic] = msg.data
            if topic == TOPIC_SEAL:
                cycles.append(Cycle(msg.sequence, msg.log_time_ns, payloads, sensors, segment))
                payloads, sensors = {}, []
        else:
            sensors.append(msg)
    if payloads:
        number = cycle_field(next(iter(payloads.values())))
        t_ns = max(m.log_time_ns for m in messages if m.topic in payloads)
        cycles.append(Cycle(number, t_ns, payloads, sensors, segment))
    return cycles


def parse_json(data: bytes, topic: str, segment: str) -> object:
    """A stored message's data as JSON; ``PayloadError`` (a ``LogReadError``) if it is not.

    orjson refuses nesting past 1024 levels itself, so a hostile payload costs one bounded
    parse; the error names the segment and topic instead of surfacing as a traceback."""
    try:
        return orjson.loads(data)
    except orjson.JSONDecodeError as err:
        raise PayloadError(segment, topic, f"not JSON ({err})") from err


def cycle_field(data: bytes) -> int:
    """The ``cycle`` of an unsealed message, or -1 when its data does not say (damage)."""
    try:
        value = orjson.loads(data).get("cycle", -1)
        return value if type(value) is int else -1
    except (orjson.JSONDecodeError, AttributeError):
        return -1


class HotAssembler:
    """The hot tier: one message per layer and a seal per cycle (PROFILE section 5)."""

    closer_topic = TOPIC_SEAL

    def __call__(self, messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
        return assemble_hot(messages, segment)
