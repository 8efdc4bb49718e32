"""The one seal check: one cycle against its seal, beside the hash chain (``chain``).

Each seal names the digests of its cycle's layer messages and the digest of the previous
seal, and from profile 1.3 a digest over all of the cycle's sensor readings. ``verify_cycle``
recomputes them (and the digests of the sensor readings its evidence cites) and says what
differs; every reader that shows whether a decision verifies asks it,
and the whole-log verification (``trace_runtime.verification``) is built on it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from hashlib import sha256
from typing import TYPE_CHECKING, Any, Literal

import orjson

from trace_runtime.chain import digest, sensor_cover, sensor_line
from trace_runtime.encoding.partial import METRICS_PERCEPTION, SEAL_FIELDS
from trace_runtime.records import LAYER_TOPICS, SENSOR_PREFIX, TOPIC_PERCEPTION, TOPIC_SEAL

if TYPE_CHECKING:
    from trace_runtime.encoding.cycles import Cycle, RawMessage

__all__ = ["SealState", "SealStatus", "verify_cycle"]


SealState = Literal["verified", "summarised", "modified", "broken_link", "unsealed"]


@dataclass(frozen=True, slots=True)
class SealStatus:
    """Whether one cycle matches its seal, and its seal the previous one.

    ``state``: ``verified`` (every layer message and evidenced sensor reading matches the
    seal; the link to the previous seal holds or was not asked about), ``summarised`` (a warm
    summary cycle: the seal and its link verify, the layer payloads are not retained),
    ``modified`` (a message differs from what the seal names, or the seal is malformed),
    ``broken_link`` (content matches, but the seal does not name ``prev_seal_digest``),
    ``unsealed`` (layer messages without a seal). ``seal_digest`` is what the next cycle's
    seal must name as ``prev``. A 1.3 seal covers every sensor reading of its cycle (a reading
    added, removed, changed or moved makes the cycle ``modified``); before 1.3 only the
    evidence refs that name a reading (sealed with the perception message) carry its digest.
    ``evidence_mismatch`` lists the readings that differ from their refs.
    """

    cycle: int
    t_ns: int
    state: SealState
    seal_digest: str | None = None
    prev: str | None = None
    link: Literal["ok", "broken", "unchecked"] = "unchecked"
    dropped: int = 0
    modified: tuple[str, ...] = ()
    missing: tuple[str, ...] = ()
    extra: tuple[str, ...] = ()
    summarised: tuple[str, ...] = ()
    evidence_checked: int = 0
    evidence_unresolved: int = 0
    evidence_mismatch: tuple[str, ...] = ()
    sensors_uncited: int = 0
    """Sensor readings in the cycle that neither the seal (before profile 1.3) nor a
    digest-carrying evidence ref covers: the chain does not cover them."""
    external: tuple[dict[str, Any], ...] = ()
    """Evidence refs naming a message in an external recording (PROFILE section 11), as
    JSON: sealed with the perception message, checked only against the recording itself
    (``trace_runtime.reading.recordings``)."""
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.state in ("verified", "summarised") and not self.evidence_mismatch

    def describe(self) -> str:
        """One line for people, e.g. ``modified: /trace/action differs from its seal``."""
        evidence = ""
        if self.evidence_mismatch:
            evidence = (
                f"; sensor reading {', '.join(self.evidence_mismatch)} does not match "
                "the digest its evidence ref names"
            )
        if self.state == "verified":
            link = "" if self.link == "ok" else " (link to the previous seal not checked)"
            return f"seal verifies{link}{evidence}"
        if self.state == "summarised":
            return f"summarised (chain verified, payloads not retained){evidence}"
        return f"{self.state.replace('_', ' ')}: {self.detail}{evidence}"


_SealParts = tuple[int, int, dict[str, str], str, int, tuple[int, str] | None]
"""A seal's (cycle, t_ns, digests, prev, dropped, sensors): ``sensors`` is the (count,
digest) of a 1.3 seal, None before."""


def _parse_seal(data: bytes) -> _SealParts | None:
    """The seal's parts, or None when it is not a valid seal record. The seal's shape
    (``partial.SEAL_FIELDS``) reads it straight from the bytes; what the shape declines takes
    the full parse (``_parse_seal_in_full``), which decides alone what is valid (the shape is
    pinned to it by property tests)."""
    fields_ = SEAL_FIELDS.decode(data)
    if fields_ is not None:
        cover = fields_.sensors
        sensors = None if cover is None else (cover.count, cover.digest)
        return fields_.cycle, fields_.t_ns, fields_.digests, fields_.prev, fields_.dropped, sensors
    return _parse_seal_in_full(data)


def _parse_seal_in_full(data: bytes) -> _SealParts | None:
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError:
        return None
    if not isinstance(value, dict):
        return None
    cycle, t_ns = value.get("cycle"), value.get("t_ns")
    digests, prev, dropped = value.get("digests"), value.get("prev"), value.get("dropped", 0)
    if not (
        type(cycle) is int
        and type(t_ns) is int
        and isinstance(digests, dict)
        and isinstance(prev, str)
        and type(dropped) is int
    ):
        return None
    for topic, named in digests.items():  # a loop, not all(...): no generator a cycle
        if not (isinstance(topic, str) and isinstance(named, str)):
            return None
    cover = value.get("sensors")
    if cover is None:
        return cycle, t_ns, digests, prev, dropped, None
    if not isinstance(cover, dict) or cover.keys() != {"count", "digest"}:
        return None
    count, readings = cover["count"], cover["digest"]
    if type(count) is not int or not isinstance(readings, str):
        return None
    return cycle, t_ns, digests, prev, dropped, (count, readings)


def _sensor_problem(
    cycle: Cycle,
    sealed: tuple[int, str],
    hexes: list[str | None],
    sensor_digest: Callable[[RawMessage], str] | None,
) -> str | None:
    """What differs between the cycle's sensor readings and the (count, digest) its 1.3
    seal covers them with; None when they match. ``hexes`` (the SHA-256 hex of each
    reading's data, by its place in ``cycle.sensors``; None for a reading the seal does not
    cover) is filled, so the evidence check hashes no reading twice."""
    lines = []
    for reading in cycle.sensors:
        if not reading.topic.startswith(SENSOR_PREFIX):
            hexes.append(None)
            continue  # a channel the profile does not define: readers ignore it (§10)
        hexed = (
            sha256(reading.data).hexdigest() if sensor_digest is None else sensor_digest(reading)
        )
        hexes.append(hexed)
        lines.append(sensor_line(reading.topic, reading.sequence, reading.log_time_ns, hexed))
    count, readings = sensor_cover(lines)
    if count != sealed[0]:
        return f"the seal covers {sealed[0]} sensor reading(s), the log has {count}"
    if readings != sealed[1]:
        return "the cycle's sensor readings differ from the seal's sensors digest"
    return None


def verify_cycle(
    cycle: Cycle,
    prev_seal_digest: str | None = None,
    *,
    perception_json: Any = None,
    sensor_digest: Callable[[RawMessage], str] | None = None,
) -> SealStatus:
    """Check one cycle: its layer messages (and evidenced sensor readings) against its seal,
    and, when ``prev_seal_digest`` is given, the seal's link to the previous seal.

    Works on every tier through the reader's ``Cycle``: for a warm summary cycle the layer
    digests cannot be recomputed, so it is ``summarised`` when its seal and link hold.
    ``perception_json``: the cycle's perception message already parsed by the caller (the
    evidence check then does not parse it a second time); it must be the parse of the stored
    bytes, which the seal check covers. ``sensor_digest``: gives the SHA-256 hex of a sensor
    message's data, for a caller that already hashed the cycle's readings (the metrics'
    sensor window); it must be the digest of the stored data.
    """
    seal_data = cycle.payloads.get(TOPIC_SEAL)
    if seal_data is None:
        topics = ", ".join(sorted(cycle.payloads)) or "no layer messages"
        return SealStatus(cycle.cycle, cycle.t_ns, "unsealed", detail=f"no seal ({topics})")
    seal_digest = digest(seal_data)
    parsed = _parse_seal(seal_data)
    if parsed is None:
        return _unreadable_seal(cycle, seal_digest)
    number, t_ns, digests, prev, dropped, sealed_sensors = parsed
    modified, missing, summarised, extra = _compare_layers(cycle, digests)
    sensor_problem = None
    hexes: list[str | None] | None = None
    if sealed_sensors is not None and cycle.summary is None:
        # (a warm summary keeps only the readings its evidence cites: not checkable here)
        hexes = []
        sensor_problem = _sensor_problem(cycle, sealed_sensors, hexes, sensor_digest)
    external: list[dict[str, Any]] = []
    found = _check_cited(
        cycle,
        digests=digests,
        modified=modified,
        perception_json=perception_json,
        external=external,
        hashes=_Hashes(cycle.sensors, hexes, sensor_digest),
    )
    checked, unresolved, bad, uncited = found or (0, 0, [], len(cycle.sensors))
    if sealed_sensors is not None:
        uncited = 0  # the seal covers every reading, cited or not
    problems = _problems(cycle, number, t_ns, (modified, missing, extra), sensor_problem)
    link = _link(prev, prev_seal_digest)
    state, detail = _verdict(problems, prev, prev_seal_digest, summarised=bool(summarised))
    head = (cycle.cycle, cycle.t_ns, state, seal_digest, prev, link, dropped)
    layers = (tuple(modified), tuple(missing), tuple(extra), tuple(summarised))
    evidence = (checked, unresolved, tuple(bad), uncited, tuple(external))
    return _seal_status(*head, *layers, *evidence, detail)


def _unreadable_seal(cycle: Cycle, seal_digest: str) -> SealStatus:
    return SealStatus(
        cycle.cycle,
        cycle.t_ns,
        "modified",
        seal_digest,
        modified=(TOPIC_SEAL,),
        detail="the seal is not a valid seal record",
    )


def _problems(
    cycle: Cycle,
    number: int,
    t_ns: int,
    layers: tuple[list[str], list[str], list[str]],
    sensor_problem: str | None,
) -> list[str]:
    """What the seal and the stored cycle disagree on: its number or time, its layers
    (modified, missing, extra), its sensor readings."""
    problems: list[str] = []
    if number != cycle.cycle or t_ns != cycle.t_ns:
        problems.append(
            f"the seal says cycle {number} at {t_ns} ns, the log stores it as cycle "
            f"{cycle.cycle} at {cycle.t_ns} ns"
        )
    if any(layers):
        problems += _layer_problems(*layers)
    if sensor_problem is not None:
        problems.append(sensor_problem)
    return problems


def _link(prev: str, prev_seal_digest: str | None) -> Literal["ok", "broken", "unchecked"]:
    """Whether the seal names the previous one (unchecked when it is not known)."""
    if prev_seal_digest is None:
        return "unchecked"
    return "ok" if prev == prev_seal_digest else "broken"


def _check_cited(
    cycle: Cycle,
    *,
    digests: dict[str, str],
    modified: list[str],
    perception_json: Any,
    external: list[dict[str, Any]],
    hashes: _Hashes,
) -> tuple[int, int, list[str], int] | None:
    """The evidence refs of an intact perception message checked against the readings they
    cite: (checked, unresolved, bad, uncited); None without such a message. Sensor readings
    before profile 1.3 are not sealed themselves: the refs that name them carry their
    digests, and the refs are sealed with the perception message."""
    perception = cycle.payloads.get(TOPIC_PERCEPTION)
    if perception is None or TOPIC_PERCEPTION in modified:
        return None
    if perception_json is None and TOPIC_PERCEPTION in digests:
        return _check_evidence_shape(cycle, perception, external, hashes)
    found = _check_evidence(cycle, perception, hashes, perception_json, external)
    assert found is not None  # whole=True: never None
    return found


class _Hashes:
    """The SHA-256 hex of a cycle's sensor readings by their place in ``cycle.sensors``:
    those the seal's sensor cover hashed (``hexes``), the others from ``given`` or hashed
    here. Places, not a lookup by ``id()`` through a closure: it runs for every cited
    reading of every cycle."""

    __slots__ = ("given", "hexes", "sensors")

    def __init__(
        self,
        sensors: Sequence[RawMessage],
        hexes: list[str | None] | None,
        given: Callable[[RawMessage], str] | None,
    ) -> None:
        self.sensors = sensors
        self.hexes = hexes
        self.given = given

    def of(self, index: int) -> str:
        hexes = self.hexes
        found = hexes[index] if hexes is not None else None
        if found is not None:
            return found
        reading = self.sensors[index]
        return sha256(reading.data).hexdigest() if self.given is None else self.given(reading)


def _check_evidence_shape(
    cycle: Cycle,
    perception: bytes,
    external: list[Any],
    hashes: _Hashes,
) -> tuple[int, int, list[str], int]:
    """``_check_evidence`` of a perception whose bytes match its seal, its entities' refs
    read as the metrics' perception shape (ids and refs only) rather than the whole JSON.

    A ref into an external recording is handed on whole (``SealStatus.external``), so a
    perception holding one is read again in full, as is one the shape declines. Only a
    sealed, matching perception is read this way: its bytes are the ones its writer sealed."""
    shaped = METRICS_PERCEPTION.decode(perception)
    if shaped is not None:
        found = _check_evidence(cycle, perception, hashes, shaped, None, whole=False)
        if found is not None:
            return found
    checked = _check_evidence(cycle, perception, hashes, None, external)
    assert checked is not None
    return checked


def _compare_layers(
    cycle: Cycle, digests: dict[str, str]
) -> tuple[list[str], list[str], list[str], list[str]]:
    """The cycle's layer messages against the digests its seal names: (modified, missing,
    summarised, extra) topics."""
    modified: list[str] = []
    missing: list[str] = []
    summarised: list[str] = []
    for topic, expected in digests.items():
        data = cycle.payloads.get(topic)
        if data is None:
            (summarised if cycle.summary is not None else missing).append(topic)
        elif sha256(data).hexdigest() != expected:  # (no wrapper call: 4 a cycle)
            modified.append(topic)
    # A layer the seal does not name was added. A /trace channel this reader does not know
    # and the seal does not name is ignored, as PROFILE section 10 asks of every reader.
    extra = [t for t in cycle.payloads if t in LAYER_TOPICS and t not in digests]
    return modified, missing, summarised, extra


def _layer_problems(modified: list[str], missing: list[str], extra: list[str]) -> list[str]:
    problems: list[str] = []
    if modified:
        verb = "differs" if len(modified) == 1 else "differ"
        problems.append(f"{', '.join(modified)} {verb} from the seal's digest")
    if missing:
        problems.append(", ".join(missing) + " named by the seal but not in the log")
    if extra:
        problems.append(", ".join(extra) + " not named by the seal")
    return problems


def _verdict(
    problems: list[str], prev: str, prev_seal_digest: str | None, *, summarised: bool
) -> tuple[SealState, str]:
    """The cycle's state and its detail: content problems first, then the link."""
    if problems:
        return "modified", "; ".join(problems)
    if prev_seal_digest is not None and prev != prev_seal_digest:
        return "broken_link", (
            f"the seal names previous seal {prev[:12]}…, the chain has {prev_seal_digest[:12]}…"
        )
    return ("summarised" if summarised else "verified"), ""


# The slot setters of SealStatus in field order. Its frozen dataclass __init__ sets each of
# the 17 fields through object.__setattr__ (3-5 us); metrics checks every cycle's seal, so
# verify_cycle fills the slots directly (about half of that).
_SEAL_STATUS_SETTERS = tuple(getattr(SealStatus, f.name).__set__ for f in fields(SealStatus))


def _seal_status(*values: Any) -> SealStatus:
    """``SealStatus(*values)``, every field given in order: the same value, built faster."""
    status = object.__new__(SealStatus)
    for set_field, value in zip(_SEAL_STATUS_SETTERS, values, strict=True):
        set_field(status, value)
    return status


class _Readings:
    """A cycle's sensor readings found by (topic, sequence), else by (topic, log time)."""

    __slots__ = ("_by_sequence", "_by_time", "_sensors")

    def __init__(self, sensors: Sequence[RawMessage]) -> None:
        self._sensors = sensors
        self._by_sequence = {(m.topic, m.sequence): i for i, m in enumerate(sensors)}
        self._by_time: dict[tuple[Any, Any], int] | None = None  # built on the first miss

    def find(self, topic: Any, sequence: Any, log_time_ns: Any) -> int | None:
        index = self._by_sequence.get((topic, sequence)) if sequence is not None else None
        if index is None:
            if self._by_time is None:
                self._by_time = {(m.topic, m.log_time_ns): i for i, m in enumerate(self._sensors)}
            index = self._by_time.get((topic, log_time_ns))
        return index


def _check_evidence(
    cycle: Cycle,
    perception: bytes,
    hashes: _Hashes,
    parsed: Any = None,
    external: list[Any] | None = None,
    *,
    whole: bool = True,
) -> tuple[int, int, list[str], int] | None:
    """Check the evidence refs that carry a digest against the cycle's sensor messages.

    Returns (refs checked, refs unresolved, readings that differ, readings no ref cites).
    Refs into an external recording are not looked for in the cycle: they are appended to
    ``external`` (when given) for the caller to check against the recording. With
    ``whole=False`` (``parsed`` holds only the shape's fields of each ref) a ref into an
    external recording gives None instead: the caller reads the whole perception.
    """
    try:
        value = parsed if parsed is not None else orjson.loads(perception)
        entities = value.get("entities") or ()
    except (orjson.JSONDecodeError, AttributeError):
        return 0, 0, [], len(cycle.sensors)
    readings = _Readings(cycle.sensors)
    digests: dict[int, str] = {}
    checked = unresolved = 0
    bad: list[str] = []
    for entity in entities:
        for evidence in entity.get("evidence") or ():
            ref = evidence.get("ref")
            if not ref:
                continue
            if isinstance(ref.get("recording"), str):
                if not whole:
                    return None
                if external is not None:
                    external.append(ref)
                continue
            if not ref.get("digest"):
                continue
            topic = ref.get("topic")
            index = readings.find(topic, ref.get("sequence"), ref.get("log_time_ns"))
            if index is None:
                unresolved += 1
                continue
            checked += 1
            if index not in digests:
                digests[index] = hashes.of(index)
            if digests[index] != ref["digest"]:
                label = f"{topic}#{cycle.sensors[index].sequence}"
                if label not in bad:
                    bad.append(label)
    return checked, unresolved, bad, len(cycle.sensors) - len(digests)
