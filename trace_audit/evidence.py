"""Evidence in external recordings, as an investigator reads it: resolved, checked, decoded.

``trace_runtime.reading.recordings`` finds the message an external evidence ref names (e.g. in a
rosbag2 MCAP) and checks its digest without decoding it. This module adds what a person
needs to see: the message decoded with the library ROS 2 tools use (``mcap-ros2-support``,
the ``ros2`` extra, imported only here and only when a CDR message is decoded), in full as
bounded typed JSON and in a few readable lines (``trace_audit.readings``), with the region
of it the decision cited. ``describe_refs`` is what ``explain`` and the incident report call
for a decision's refs; ``describe_channel_refs`` for the messages its actuator channels
were read from (profile 1.4), in a recording or in the log itself.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from trace_audit.jsonout import OMIT_EMPTY
from trace_audit.readings import CitedRegion, cited_region, message_data, message_lines
from trace_audit.sensor_window import SensorWindow, check_in_recordings
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import LogReadError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import ExternalCheck, ExternalState, Recordings, is_external
from trace_runtime.session import TIERS

__all__ = [
    "ExternalEvidence",
    "decode_message",
    "describe_channel_refs",
    "describe_refs",
    "open_recordings",
    "recordings_for",
]


@dataclass(frozen=True, slots=True)
class ExternalEvidence:
    """One evidence ref of a decision into a recording (or, for an actuator channel, into
    this log) and what became of it: resolved and decoded, broken, or unresolved."""

    entity: str
    """The entity whose evidence cites the message ('' for an actuator channel's ref)."""
    recording: str
    """The recording's name; '' when the message is in this log (a channel's ref)."""
    topic: str
    log_time_ns: int | None
    state: ExternalState
    detail: str = ""
    """Why it is broken or unresolved ('' when resolved)."""
    schema: str = ""
    """The message's type, e.g. ``sensor_msgs/msg/LaserScan`` (when resolved)."""
    message: Any = None
    """The decoded message in full, as bounded typed JSON (``readings.message_data``);
    None when not resolved or not decoded."""
    lines: tuple[str, ...] = ()
    """The decoded message for people (``readings.message_lines``), or why it was not
    decoded."""
    sensor: str = ""
    """The evidence item's sensor name ('' for a channel's ref)."""
    region: CitedRegion | None = field(default=None, metadata={OMIT_EMPTY: True})
    """The part of the reading the decision cited, read against the decoded message."""
    channel: str | None = field(default=None, metadata={OMIT_EMPTY: True})
    """The actuator channel whose ``actual`` was read from the message (None for an
    entity's evidence, and then left out of the JSON)."""


def open_recordings(paths: Sequence[str | Path]) -> Recordings | None:
    """``Recordings`` over the given files or directories; None when there are none."""
    return Recordings.open(paths) if paths else None


def recordings_for(
    segments: Iterable[Segment] | Log, given: Sequence[str | Path] = ()
) -> Recordings | None:
    """The one resolution of evidence every command uses: the recordings the log's segments
    declare (profile 1.4, found where the robot said, relative to its root), with those
    ``given`` (``--evidence``) taking precedence for a moved copy. None when the log
    declares none and none were given; a declared recording that is not there is in
    ``Recordings.missing`` (its refs are unresolved: unknown, not broken)."""
    opened = open_recordings(given)
    found = segments.segments if isinstance(segments, Log) else segments
    sessions = [(_base_of(s.path), s.session.recordings) for s in found if s.session.recordings]
    if not sessions:
        return opened
    return Recordings.declared(sessions, opened)


def _base_of(segment: Path) -> Path:
    """The folder a segment's declared recording paths are relative to: its log root when it
    lies in a tier folder, else its own folder (a single-file log)."""
    folder = segment.parent
    return folder.parent if folder.name in TIERS else folder


def describe_refs(
    perception: object, recordings: Recordings | None, *, decode: bool = True
) -> list[ExternalEvidence]:
    """Every external evidence ref of a perception message (parsed JSON), checked against
    ``recordings`` (None: each is unresolved) and, when resolved, decoded."""
    out: list[ExternalEvidence] = []
    for entity_id, evidence, ref in _external_refs(perception):
        check = check_in_recordings(ref, recordings)
        shown = _shown(check) if decode and check.state == "resolved" else _NOT_DECODED
        region = cited_region(evidence.get("region"), shown.decoded)
        sensor = str(evidence.get("sensor") or "")
        out.append(_evidence(ref, check, shown, entity=entity_id, sensor=sensor, region=region))
    return out


def describe_channel_refs(
    execution: object, recordings: Recordings | None, sensors: Sequence[RawMessage] = ()
) -> list[ExternalEvidence]:
    """The message each actuator channel of an execution message (parsed JSON) cites as
    where its ``actual`` was read from: in a recording, checked as an entity's external
    evidence is (``Recordings.check``), or in this log, among the cycle's ``sensors``."""
    out: list[ExternalEvidence] = []
    for channel, ref in _channel_refs(execution):
        if is_external(ref):
            check = check_in_recordings(ref, recordings)
        else:
            check = _check_in_log(ref, sensors)
        shown = _shown(check) if check.state == "resolved" else _NOT_DECODED
        out.append(_evidence(ref, check, shown, channel=channel))
    return out


def _evidence(
    ref: Mapping[str, object],
    check: ExternalCheck,
    shown: _Shown,
    *,
    entity: str = "",
    sensor: str = "",
    region: CitedRegion | None = None,
    channel: str | None = None,
) -> ExternalEvidence:
    """What became of one ref: an entity's evidence (``entity``, ``sensor``, ``region``) or
    an actuator channel's (``channel``)."""
    return ExternalEvidence(
        entity,
        str(ref.get("recording")) if entity else check.recording,
        str(ref.get("topic")),
        _time_of(ref),
        check.state,
        _detail(check),
        schema=shown.schema,
        message=shown.message,
        lines=shown.lines,
        sensor=sensor,
        region=region,
        channel=channel,
    )


def _time_of(ref: Mapping[str, object]) -> int | None:
    stamp = ref.get("log_time_ns")
    return stamp if type(stamp) is int else None


def _external_refs(
    perception: object,
) -> Iterable[tuple[str, Mapping[str, Any], dict[str, object]]]:
    """(entity id, evidence item, ref) of each ref into a recording."""
    if not isinstance(perception, dict):
        return
    for entity in perception.get("entities") or ():
        if not isinstance(entity, dict):
            continue
        for evidence in entity.get("evidence") or ():
            ref = evidence.get("ref") if isinstance(evidence, dict) else None
            if isinstance(ref, dict) and is_external(ref):
                yield str(entity.get("id")), evidence, ref


def _channel_refs(execution: object) -> Iterable[tuple[str, dict[str, object]]]:
    """(channel name, ref) of each actuator channel that cites a message."""
    channels = execution.get("channels") if isinstance(execution, dict) else None
    for channel in channels if isinstance(channels, list) else ():
        ref = channel.get("ref") if isinstance(channel, dict) else None
        if isinstance(ref, dict):
            yield str(channel.get("name") or "?"), ref


def _check_in_log(ref: Mapping[str, object], sensors: Sequence[RawMessage]) -> ExternalCheck:
    """A ref into this log checked against the cycle's sensor readings (``SensorWindow``'s
    rule): resolved, broken when a reading of that topic and time differs from it, or
    unresolved when the cycle holds none (an older reading: not checked here)."""
    window = SensorWindow(0)
    window.push(sensors)
    why = window.resolve(ref)
    at = (ref.get("topic"), ref.get("log_time_ns"))
    same = [m for m in sensors if (m.topic, m.log_time_ns) == at]
    if not why:
        return ExternalCheck("resolved", "", message=same[0] if same else None)
    return ExternalCheck("broken" if same else "unresolved", "", why)


@dataclass(frozen=True, slots=True)
class _Shown:
    """A resolved message decoded: its type, the value, its JSON and its lines."""

    schema: str = ""
    decoded: object | None = None
    message: Any = None
    lines: tuple[str, ...] = ()


_NOT_DECODED = _Shown()


def _shown(check: ExternalCheck) -> _Shown:
    """The message a check found, decoded: from its recording file, or as JSON when it is a
    reading of this log (``path`` None)."""
    found = check.message
    if found is None:
        return _NOT_DECODED
    try:
        if check.path is None:
            schema, value = "", _parse_json(found)
        else:
            schema, value = decode_message(check.path, found.topic, found.data)
    except LogReadError as err:
        return _Shown(lines=(f"(not decoded: {err.reason})",))
    return _Shown(schema, value, message_data(value), message_lines(value))


def _parse_json(found: RawMessage) -> object:
    try:
        return orjson.loads(found.data)
    except orjson.JSONDecodeError as err:
        raise LogReadError(found.topic, f"not JSON ({err})") from err


def decode_message(path: Path, topic: str, data: bytes) -> tuple[str, object]:
    """Decode one message of ``topic`` in the MCAP file at ``path``: (schema name, value).

    CDR (ROS 2) with a ``ros2msg`` schema decodes through ``mcap-ros2-support``; JSON is
    parsed. The value is JSON or a ROS 2 message (a class the decoder builds from the
    schema), read by its fields. Raises ``LogReadError`` when the file has no summary to
    find the channel's schema in, or the encoding is one this tool does not decode.
    """
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
    except (OSError, McapError, ValueError) as err:
        raise LogReadError(str(path), f"cannot read its summary ({err})") from err
    if summary is None:
        raise LogReadError(str(path), "no summary (not closed): channel schemas unknown")
    channel = next((c for c in summary.channels.values() if c.topic == topic), None)
    if channel is None:
        raise LogReadError(str(path), f"no channel {topic} in its summary")
    schema = summary.schemas.get(channel.schema_id)
    name = schema.name if schema is not None else ""
    if channel.message_encoding == "json":
        return name, orjson.loads(data)
    if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
        raise LogReadError(
            str(path), f"{topic}: message encoding {channel.message_encoding!r} not decoded"
        )
    try:
        from mcap_ros2.decoder import DecoderFactory
    except ImportError as err:
        raise LogReadError(
            str(path), "decoding ROS 2 messages needs the ros2 extra (mcap-ros2-support)"
        ) from err
    decoder = DecoderFactory().decoder_for("cdr", schema)
    if decoder is None:
        raise LogReadError(str(path), f"{topic}: no ROS 2 decoder for {name}")
    try:
        return name, decoder(data)
    except (McapError, ValueError, IndexError, UnicodeDecodeError) as err:
        raise LogReadError(str(path), f"{topic}: does not decode as {name} ({err})") from err


def _detail(check: ExternalCheck) -> str:
    """Why a ref is broken or unresolved; for one resolved by its digest near its time, how
    far the recorded message is from the time the ref names."""
    if check.state == "resolved" and check.shift_ns:
        return f"recorded {check.shift_ns / 1e9:+.3f} s from the ref's time (matched by digest)"
    return check.detail
