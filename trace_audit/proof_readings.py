"""What a proof bundle carries of the readings its cycle cites, and how they are checked:
the readings in the TRACE file a profile 1.3 seal covers (``sensors``: their lines against
the seal's), and the messages of the robot's recordings its evidence refs cite (``recorded``,
from ``trace-proof/4``: each against a ref sealed in the bundle's own messages, by topic,
time within ``NEAR_NS`` and data digest), so a cited rosbag2 message is checked without the
recording."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator, Mapping

import orjson

from trace_audit.proof_data import BadBundleError, DataReader, deflated, field_of
from trace_runtime.chain import sensor_cover, sensor_line
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.reading.recordings import NEAR_NS, Recordings, is_external
from trace_runtime.records import TOPIC_EXECUTION, TOPIC_PERCEPTION

__all__ = ["check_readings", "check_recorded", "readings_of", "recorded_of"]

Steps = list[tuple[str, bool, str]]
_READING_FIELDS = frozenset({"topic", "sequence", "log_time_ns", "data"})
_RECORDED_FIELDS = frozenset({"recording", "topic", "log_time_ns", "sequence", "data"})


def readings_of(found: Cycle, covered: bool) -> list[dict[str, str | int]]:
    """The cycle's readings in the TRACE file, when its seal covers them (profile 1.3)."""
    return [
        {
            "topic": m.topic,
            "sequence": m.sequence,
            "log_time_ns": m.log_time_ns,
            "data": deflated(m.data),
        }
        for m in (found.sensors if covered else ())
    ]


def recorded_of(found: Cycle, recordings: Recordings | None) -> list[dict[str, str | int]]:
    """The recording messages the cycle's refs cite that ``recordings`` resolve (a ref
    into a recording not here is left out: ``verify-proof`` counts it as not carried)."""
    carried: list[dict[str, str | int]] = []
    seen: set[tuple[str, str, int]] = set()
    for ref in _external_refs(found.payloads):
        check = recordings.check(ref) if recordings is not None else None
        message = check.message if check is not None and check.state == "resolved" else None
        if message is None:
            continue
        key = (str(ref["recording"]), message.topic, message.log_time_ns)
        if key not in seen:
            seen.add(key)
            carried.append(
                {
                    "recording": key[0],
                    "topic": message.topic,
                    "log_time_ns": message.log_time_ns,
                    "sequence": message.sequence,
                    "data": deflated(message.data),
                }
            )
    return carried


def _external_refs(payloads: Mapping[str, bytes]) -> Iterator[dict[str, object]]:
    """Every external evidence ref of the perception's entities and the execution's
    channels (profile 1.4), as sealed."""
    for topic in (TOPIC_PERCEPTION, TOPIC_EXECUTION):
        data = payloads.get(topic)
        if data is None:
            continue
        try:
            value = orjson.loads(data)
        except orjson.JSONDecodeError:
            continue
        yield from _refs_in(value)


def _refs_in(value: object) -> Iterator[dict[str, object]]:
    if not isinstance(value, dict):
        return
    for entity in value.get("entities") or ():
        for evidence in (entity.get("evidence") or ()) if isinstance(entity, dict) else ():
            ref = evidence.get("ref") if isinstance(evidence, dict) else None
            if isinstance(ref, dict) and is_external(ref):
                yield ref
    for channel in value.get("channels") or ():
        ref = channel.get("ref") if isinstance(channel, dict) else None
        if isinstance(ref, dict) and is_external(ref):
            yield ref


def check_readings(
    bundle: Mapping[str, object], seal: Mapping[str, object], steps: Steps, read: DataReader
) -> bool:
    """The bundle's sensor readings against the seal's ``sensors``: False when they differ."""
    lines = []
    for m in field_of(bundle, "sensors", list):
        if not isinstance(m, dict) or set(m) != _READING_FIELDS:
            raise BadBundleError("a sensor reading is not topic, sequence, log_time_ns, data")
        topic, sequence, at = m["topic"], m["sequence"], m["log_time_ns"]
        if not isinstance(topic, str) or not all(type(v) is int for v in (sequence, at)):
            raise BadBundleError("a sensor reading's topic, sequence or time is malformed")
        hexed = hashlib.sha256(read(m["data"], f"reading {topic}")).hexdigest()
        lines.append(sensor_line(topic, sequence, at, hexed))
    sealed = seal.get("sensors")
    if sealed is None:
        if lines:
            raise BadBundleError("sensor readings given for a seal that does not cover them")
        steps.append(("sensors", True, "not covered by this seal (profile 1.2 or earlier)"))
        return True
    cover = count, _ = sensor_cover(lines)
    if not isinstance(sealed, dict) or (sealed.get("count"), sealed.get("digest")) != cover:
        steps.append(("sensors", False, f"the {count} reading(s) differ from the seal's"))
        return False
    steps.append(("sensors", True, f"{count} sensor reading(s) match the seal"))
    return True


def check_recorded(
    bundle: Mapping[str, object], messages: Mapping[str, bytes], steps: Steps, read: DataReader
) -> bool:
    """The recording messages the bundle carries, each against a ref sealed in its
    ``messages`` (already checked against the seal): same recording and topic, its time
    within ``NEAR_NS`` of the ref's, its data the ref's digest. False when one matches none."""
    refs = list(_external_refs(messages))
    matched = 0
    for m in field_of(bundle, "recorded", list):
        if not isinstance(m, dict) or set(m) != _RECORDED_FIELDS:
            raise BadBundleError("a recorded message is not recording, topic, time, sequence, data")
        name, topic, at = m["recording"], m["topic"], m["log_time_ns"]
        if not isinstance(name, str) or not isinstance(topic, str) or type(at) is not int:
            raise BadBundleError("a recorded message's recording, topic or time is malformed")
        digest = hashlib.sha256(read(m["data"], f"recorded {topic}")).hexdigest()
        if not any(_names(ref, name, topic, at, digest) for ref in refs):
            steps.append(("recorded", False, f"{name} {topic} at {at}: no sealed ref cites it"))
            return False
        matched += 1
    cited = len({(str(r.get("recording")), str(r.get("topic")), r.get("digest")) for r in refs})
    left = f"; {cited - matched} cited, not carried" if cited > matched else ""
    steps.append(("recorded", True, f"{matched} cited recording message(s) match their refs{left}"))
    return True


def _names(ref: Mapping[str, object], name: str, topic: str, at: int, digest: str) -> bool:
    t_ns = ref.get("log_time_ns")
    return (
        ref.get("recording") == name
        and ref.get("topic") == topic
        and ref.get("digest") == digest
        and type(t_ns) is int
        and abs(t_ns - at) <= NEAR_NS
    )
