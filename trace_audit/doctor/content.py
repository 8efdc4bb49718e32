"""The message level of ``doctor``: each /trace message's bytes, stamp and schema, and each
cycle's layout (sensors, layers, seal), numbering, time and evidence refs.

Messages arrive in file order from ``structure``; cycles are grouped as PROFILE section 5
says readers group them (everything after one seal up to the next seal), so what is checked
here is what a reader will make of the file. The seal digests and the hash chain are checked
by ``trace_runtime.verification`` (the one verifier), whose findings ``doctor`` maps to rules.
"""

from __future__ import annotations

import itertools
import json
import re
from dataclasses import dataclass, field
from typing import Any

import orjson
from mcap.records import Message

from trace_audit.chains import DEFAULT_SENSOR_WINDOW, SensorWindow
from trace_audit.doctor.rules import SegmentDoctor
from trace_runtime.encoding.codec import decode_canonical, validate_parsed
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import RecordError
from trace_runtime.records import (
    LAYER_TOPICS,
    MESSAGE_MODELS,
    TOPIC_CHECKPOINT,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)
from trace_runtime.tier_formats.warm import SUMMARY_TOPIC

__all__ = ["CHECKPOINT_GAP_NS", "CycleCheck"]

CHECKPOINT_GAP_NS = 20_000_000_000
"""Checkpoints further apart than this in log time are noted (PROFILE section 6: a
checkpoint every 10 s, with room for a writer that checkpoints after its batch)."""

_OUTSIDE_CHUNKS = -1
"""The chunk key of every message written outside chunks: they are one stretch of the file."""

_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')
_WHITESPACE = re.compile(rb"[ \t\r\n]")
_MAX_DEPTH_TEXT = "JSON nested too deep"


def parse_canonical(data: bytes) -> tuple[Any, str]:
    """Parse /trace message data; (value, '') or (value or None, why it is not canonical)."""
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError:
        pass
    else:
        # Bytes that orjson spells back exactly are compact, unique-keyed UTF-8 JSON (what the
        # Python writer and most writers emit): the common case, without the slow checks.
        if orjson.dumps(value) == data:
            return value, ""
    if data.startswith(b"\xef\xbb\xbf"):
        return None, "starts with a byte-order mark"
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return None, "is not UTF-8"
    repeated: list[str] = []

    def unique(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        if len({k for k, _ in pairs}) != len(pairs) and not repeated:
            keys = [k for k, _ in pairs]
            repeated.append(next(k for k in keys if keys.count(k) > 1))
        return dict(pairs)

    try:
        value = json.loads(text, object_pairs_hook=unique)
    except RecursionError:
        return None, _MAX_DEPTH_TEXT
    except ValueError as err:
        return None, f"is not JSON ({err})"
    if repeated:
        return value, f"repeats the key {repeated[0]!r}"
    if _WHITESPACE.search(_STRING.sub(b'""', data)):
        return value, "has whitespace between tokens (not compact)"
    return value, ""


def _decode_canonical(topic: str, data: bytes) -> Any:
    """A /trace message's record when its bytes are canonical and valid (``codec``'s
    ``decode_canonical``: the verdict of ``parse_canonical`` and ``validate_parsed`` on
    them, half the cost); None for a topic without a model, or bytes to judge the slow way."""
    model = MESSAGE_MODELS.get(topic)
    return None if model is None else decode_canonical(model, data)


@dataclass(slots=True)
class _Open:
    """The cycle being read: messages since the last seal."""

    sensors: list[RawMessage] = field(default_factory=list)
    layers: dict[str, Any] = field(default_factory=dict)
    stamp: tuple[int, int] | None = None
    chunks: set[int] = field(default_factory=set)


class CycleCheck:
    """Checks messages as they come, one cycle at a time (bounded by one cycle plus the
    evidence window)."""

    def __init__(self, report: SegmentDoctor) -> None:
        self.report = report
        self.open = _Open()
        self.last: tuple[int, int] | None = None  # (cycle, t_ns) of the last sealed cycle
        self.window = SensorWindow(DEFAULT_SENSOR_WINDOW)
        self.checkpoints: list[tuple[int, bool]] = []  # (t_ns, final)
        self.first_t: int | None = None
        self.seals_cover_sensors = False
        """The segment's profile is 1.3 or later: each seal must carry ``sensors``."""
        self._chunk = 0  # the chunk of the message being checked (_OUTSIDE_CHUNKS: none)

    def damage(self) -> None:
        """A chunk did not decode: do not join the cycles on either side of it."""
        self.open = _Open()
        self.window.clear()

    def message(self, topic: str, message: Message, offset: int, *, in_chunk: bool = True) -> None:
        """Check one message; ``offset`` locates it (its chunk's, or its own when it was
        written outside chunks: ``in_chunk`` False, and no chunk boundary is crossed)."""
        self._chunk = offset if in_chunk else _OUTSIDE_CHUNKS
        self.report.messages += 1
        if topic == SUMMARY_TOPIC:
            self.report.summarised += 1
        if not topic.startswith("/trace/"):
            self._sensor(topic, message, offset)
            return
        canonical = None if topic == TOPIC_PERCEPTION else _decode_canonical(topic, message.data)
        if canonical is not None:
            # canonical and valid: nothing to report of its bytes; only its stamp is read
            stamp = self._stamp(topic, canonical.cycle, canonical.t_ns, message, offset)
            if stamp is not None:  # (always: the model types both as integers)
                self._place(topic, canonical, stamp, offset, sensors_given=True)
            return
        value, why = parse_canonical(message.data)
        cycle = self.open.stamp[0] if self.open.stamp else None
        if why:
            self.report.add(
                "compact-json", f"{topic} data {why}", cycle=cycle, offset=offset, key=topic + why
            )
        if not isinstance(value, dict):
            return
        stamp = self._stamp(topic, value.get("cycle"), value.get("t_ns"), message, offset)
        if topic in MESSAGE_MODELS:
            try:
                validate_parsed(MESSAGE_MODELS[topic], value)
            except RecordError as err:
                where = stamp[0] if stamp else cycle
                self.report.add(
                    "schema-valid", f"{topic}: {err}", cycle=where, offset=offset, key=str(err)
                )
        if stamp is not None:
            final = topic == TOPIC_CHECKPOINT and value.get("final") is True
            self._place(topic, value, stamp, offset, sensors_given="sensors" in value, final=final)

    def _place(
        self,
        topic: str,
        value: Any,
        stamp: tuple[int, int],
        offset: int,
        *,
        sensors_given: bool,
        final: bool = False,
    ) -> None:
        """A stamped /trace message into its cycle: a checkpoint, a layer, or the seal that
        closes the cycle. ``sensors_given``: a seal's ``sensors`` key is there."""
        if topic == TOPIC_CHECKPOINT:
            self.checkpoints.append((stamp[1], final))
        elif topic in LAYER_TOPICS:
            self._layer(topic, value, stamp, offset)
        elif topic == TOPIC_SEAL:
            if self.seals_cover_sensors and not sensors_given:
                self.report.add(
                    "seal-sensors",
                    "a seal of a profile 1.3 segment has no 'sensors': its cycle's sensor "
                    "readings are outside the chain",
                    cycle=stamp[0],
                    offset=offset,
                    key="",
                )
            self._seal(stamp, offset)

    def _sensor(self, topic: str, message: Message, offset: int) -> None:
        if self.open.layers:
            self.report.add(
                "cycle-layout",
                f"sensor message {topic} comes after the layer messages of its cycle",
                cycle=self.open.stamp[0] if self.open.stamp else None,
                offset=offset,
            )
        self.open.sensors.append(
            RawMessage(topic, message.sequence, message.log_time, message.data)
        )
        self.open.chunks.add(self._chunk)

    def _stamp(
        self, topic: str, cycle: Any, t_ns: Any, message: Message, offset: int
    ) -> tuple[int, int] | None:
        if type(cycle) is not int or type(t_ns) is not int:
            self.report.add(
                "stamp", f"{topic} message without integer cycle and t_ns", offset=offset
            )
            return None
        if message.log_time != t_ns or message.publish_time != t_ns:
            self.report.add(
                "log-time",
                f"{topic}: MCAP log_time {message.log_time} / publish_time "
                f"{message.publish_time} differ from t_ns {t_ns}",
                cycle=cycle,
                offset=offset,
                key=topic,
            )
        if message.sequence != cycle:
            self.report.add(
                "sequence",
                f"{topic}: MCAP sequence {message.sequence} differs from cycle {cycle}",
                cycle=cycle,
                offset=offset,
                key=topic,
            )
        return cycle, t_ns

    def _layer(self, topic: str, value: Any, stamp: tuple[int, int], offset: int) -> None:
        current = self.open
        self._same_cycle(topic, stamp, offset)
        if topic in current.layers:
            self.report.add(
                "one-per-cycle", f"two {topic} messages in one cycle", cycle=stamp[0], offset=offset
            )
        current.layers[topic] = value
        current.chunks.add(self._chunk)

    def _same_cycle(self, topic: str, stamp: tuple[int, int], offset: int) -> None:
        current = self.open
        if current.stamp is None:
            current.stamp = stamp
        elif current.stamp != stamp:
            self.report.add(
                "same-cycle",
                f"{topic} says cycle {stamp[0]} at {stamp[1]} ns inside cycle "
                f"{current.stamp[0]} at {current.stamp[1]} ns",
                cycle=current.stamp[0],
                offset=offset,
                key=topic,
            )

    def _seal(self, stamp: tuple[int, int], offset: int) -> None:
        self._same_cycle(TOPIC_SEAL, stamp, offset)
        current = self.open
        current.chunks.add(self._chunk)
        cycle, t_ns = stamp
        if self.first_t is None:
            self.first_t = t_ns
        if self.last is not None:
            if cycle <= self.last[0]:
                self.report.add(
                    "cycle-order",
                    f"cycle {cycle} follows cycle {self.last[0]}",
                    cycle=cycle,
                    offset=offset,
                    key="",
                )
            if t_ns < self.last[1]:
                self.report.add(
                    "time-order",
                    f"cycle {cycle} at {t_ns} ns is earlier than cycle {self.last[0]} "
                    f"at {self.last[1]} ns",
                    cycle=cycle,
                    offset=offset,
                    key="",
                )
        if len(current.chunks) > 1:
            self.report.add("cycle-in-chunk", "cycles span chunk boundaries", cycle=cycle)
        self.window.push(current.sensors)
        self._check_refs(current.layers.get(TOPIC_PERCEPTION), cycle, offset)
        self.report.cycles += 1
        self.last = stamp
        self.open = _Open()

    def _check_refs(self, perception: Any, cycle: int, offset: int) -> None:
        """In-log evidence refs against the sensor messages of this and recent cycles
        (refs into external recordings are checked by the verifier, given the recording)."""
        if not isinstance(perception, dict):
            return
        for entity in perception.get("entities") or ():
            for evidence in (entity.get("evidence") or ()) if isinstance(entity, dict) else ():
                ref = evidence.get("ref") if isinstance(evidence, dict) else None
                if not isinstance(ref, dict) or isinstance(ref.get("recording"), str):
                    continue
                why = self.window.resolve(ref)
                if not why:
                    continue
                if "digest" in why:
                    self.report.add("evidence-digest", f"an evidence ref: {why}", cycle=cycle)
                else:
                    # counted under one line: a robot whose sensor drops out does it often
                    self.report.add(
                        "evidence-resolves",
                        "evidence refs name no logged sensor message of their cycle or the "
                        f"{DEFAULT_SENSOR_WINDOW} before it",
                        cycle=cycle,
                    )

    def finish(self, *, closed: bool) -> None:
        """End of the file: a cycle left open, and the checkpoint cadence."""
        if self.open.layers:
            stamp = self.open.stamp
            text = f"layer messages of cycle {stamp[0] if stamp else '?'} have no seal"
            if closed:
                self.report.add("sealed", text, cycle=stamp[0] if stamp else None)
            else:
                self.report.add("closed", text + " (the cycle in flight when it stopped)")
        self._cadence(closed)

    def _cadence(self, closed: bool) -> None:
        if self.first_t is None or self.last is None or not self.checkpoints:
            return  # none at all: the verifier's note says so
        times = [self.first_t, *(t for t, _ in self.checkpoints)]
        widest = max(b - a for a, b in itertools.pairwise(times))
        if widest > CHECKPOINT_GAP_NS:
            self.report.add(
                "checkpoint-cadence",
                f"{widest / 1e9:.1f} s of log time without a checkpoint",
            )
        if closed and not self.checkpoints[-1][1]:
            self.report.add("checkpoint-cadence", "the last checkpoint is not marked final")
