"""Evidence in external recordings, as an investigator reads it: resolved, checked, decoded.

``trace_runtime.reading.recordings`` finds the message an external evidence ref names (e.g. in a
rosbag2 MCAP) and checks its digest without decoding it. This module adds what a person
needs to see: the message decoded with the library ROS 2 tools use (``mcap-ros2-support``,
the ``ros2`` extra, imported only here and only when a CDR message is decoded), summarised
as its type and top-level fields. ``describe_refs`` is what ``explain`` and the incident
report call for a decision's refs.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import orjson

from trace_runtime.errors import LogReadError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import ExternalCheck, ExternalState, Recordings, is_external
from trace_runtime.session import TIERS

__all__ = [
    "ExternalEvidence",
    "decode_message",
    "describe_refs",
    "open_recordings",
    "recordings_for",
]

_MAX_FIELDS = 12
_MAX_TEXT = 60


@dataclass(frozen=True, slots=True)
class ExternalEvidence:
    """One external evidence ref of a decision and what became of it."""

    entity: str
    recording: str
    topic: str
    log_time_ns: int | None
    state: ExternalState
    detail: str = ""
    """Why it is broken or unresolved ('' when resolved)."""
    schema: str = ""
    """The message's type, e.g. ``sensor_msgs/msg/LaserScan`` (when resolved)."""
    fields: tuple[tuple[str, str], ...] = ()
    """Top-level fields of the decoded message, each shortened to one line."""


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
    for entity_id, ref in _external_refs(perception):
        name = str(ref.get("recording"))
        topic = str(ref.get("topic"))
        stamp = ref.get("log_time_ns")
        t_ns = stamp if type(stamp) is int else None
        if recordings is None:
            out.append(ExternalEvidence(entity_id, name, topic, t_ns, "unresolved", "not given"))
            continue
        check = recordings.check(ref)
        schema, fields = ("", ()) if not decode or check.state != "resolved" else _decoded(check)
        out.append(
            ExternalEvidence(
                entity_id, name, topic, t_ns, check.state, check.detail, schema, fields
            )
        )
    return out


def _external_refs(perception: object) -> Iterable[tuple[str, dict[str, object]]]:
    if not isinstance(perception, dict):
        return
    for entity in perception.get("entities") or ():
        if not isinstance(entity, dict):
            continue
        for evidence in entity.get("evidence") or ():
            ref = evidence.get("ref") if isinstance(evidence, dict) else None
            if isinstance(ref, dict) and is_external(ref):
                yield str(entity.get("id")), ref


def _decoded(check: ExternalCheck) -> tuple[str, tuple[tuple[str, str], ...]]:
    assert check.message is not None and check.path is not None
    try:
        schema, value = decode_message(check.path, check.message.topic, check.message.data)
    except LogReadError as err:
        return "", (("(not decoded)", err.reason),)
    return schema, _summary(value)


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


def _summary(value: object) -> tuple[tuple[str, str], ...]:
    """Top-level fields as short text: scalars as they are, sequences by length, nested
    messages by their own first fields."""
    if isinstance(value, dict):
        items = list(value.items())
    else:
        slots = getattr(value, "__slots__", None) or list(getattr(value, "__dict__", {}))
        items = [(name, getattr(value, name)) for name in slots if not name.startswith("_")]
    return tuple((str(name), _short(field)) for name, field in items[:_MAX_FIELDS])


def _short(value: object) -> str:
    if isinstance(value, float):
        text = f"{value:.6g}"
    elif isinstance(value, bytes | bytearray):
        text = f"{len(value)} bytes"
    elif isinstance(value, list | tuple):
        head = ", ".join(_short(v) for v in value[:4])
        text = f"[{len(value)}] {head}{', …' if len(value) > 4 else ''}"
    elif isinstance(value, str | int | bool) or value is None:
        text = repr(value) if isinstance(value, str) else str(value)
    else:
        text = "{" + ", ".join(f"{k}: {v}" for k, v in _summary(value)[:3]) + "}"
    return text if len(text) <= _MAX_TEXT else text[: _MAX_TEXT - 1] + "…"
