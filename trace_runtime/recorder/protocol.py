"""The recorder's wire protocol (schemas/PROFILE.md section 13): frames, message kinds, the
version, the limits, and the checks every message a client sends goes through.

A frame is a 4-byte big-endian length and that many bytes of one compact JSON object whose
``kind`` says what it is. Plain sockets and length-prefixed JSON, not a messaging library, so
that a client in any language needs only its standard library and POSIX sockets (Debian
ships no headers of libzmq in a robot's minimal image, and a C++ client must not pull one).

``FrameReader`` cuts a byte stream into frames with bounded memory: a frame over the limit
is skipped as it arrives, never buffered, and reported once. ``parse_hello`` and
``parse_cycle`` check a message's fields and raise ``WireProtocolError`` with the reason the
recorder sends back; the records inside a cycle are checked later, by the logger's own
record models.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import orjson

from trace_runtime.errors import WireProtocolError
from trace_runtime.session import INT64_MAX, MIN_PERIOD_NS

__all__ = [
    "CLIENT_KINDS",
    "HEADER",
    "LAYERS",
    "MAX_DECLARED_DROPS",
    "MAX_FRAME_BYTES",
    "MAX_SENSORS",
    "PROTOCOL_VERSION",
    "CycleMessage",
    "FrameReader",
    "Hello",
    "Oversized",
    "SensorMessage",
    "encode_frame",
    "message_kind",
    "parse_cycle",
    "parse_hello",
    "parse_message",
]

PROTOCOL_VERSION = 1
"""The version a client names in its hello; the recorder refuses any other."""
HEADER = struct.Struct(">I")
"""The frame header: the length of the JSON body that follows, big-endian, 4 bytes."""
MAX_FRAME_BYTES = 4 * 1024 * 1024
"""The longest JSON body a recorder takes (4 MiB). A longer frame is skipped and refused."""
MAX_SENSORS = 1024
"""At most this many sensor readings in one cycle message."""
MAX_DECLARED_DROPS = 1_000_000
"""At most this many dropped cycles declared by one cycle message (a client at 1 kHz that
lost its recorder for over 16 minutes declares the rest with its next messages)."""
LAYERS = ("perception", "belief", "action", "execution")
"""The four layer fields of a cycle message, named as the logger's builder methods."""
CLIENT_KINDS = ("hello", "cycle", "stats", "flush", "bye")
"""The kinds a client sends; the recorder answers with welcome, refused, error, stats,
flushed and bye."""

_ROBOT_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
_PROFILE = re.compile(r"1(\.[0-9]+)?")
_MAX_TEXT = 256
_HELLO_FIELDS = frozenset(
    {"kind", "protocol", "robot_id", "period_ns", "clock", "software_version"}
    | {"policy_version", "profile", "recordings"}
)
MAX_RECORDINGS = 16
"""Recordings one hello may declare (each a path on the recorder's machine)."""
_CYCLE_FIELDS = frozenset({"kind", "seq", "dropped", "t_ns", "sensors", *LAYERS})
_SENSOR_FIELDS = frozenset({"topic", "data", "log_time_ns"})


def encode_frame(message: dict[str, Any], default: Callable[[Any], Any] | None = None) -> bytes:
    """One frame: the header and the compact JSON of ``message`` (``default`` turns values
    orjson does not know into JSON ones, as in ``orjson.dumps``)."""
    body = orjson.dumps(message, default=default)
    return HEADER.pack(len(body)) + body


@dataclass(frozen=True, slots=True)
class Oversized:
    """A frame whose announced length is over the limit: skipped, its bytes never kept."""

    length: int


class FrameReader:
    """Cuts the bytes a socket gives into frame bodies, in bounded memory.

    ``feed`` returns the complete frames (``bytes``) and the oversized ones (``Oversized``,
    reported when their header arrives) in stream order. The buffer holds at most one
    frame under the limit plus what one ``feed`` brought.
    """

    def __init__(self, max_frame_bytes: int = MAX_FRAME_BYTES) -> None:
        self.max_frame_bytes = max_frame_bytes
        self._buffer = bytearray()
        self._skip = 0  # bytes of an oversized frame still to be thrown away

    @property
    def pending(self) -> int:
        """Bytes of an unfinished frame held (a stream that ends here ends mid-frame)."""
        return len(self._buffer) + self._skip

    def feed(self, data: bytes) -> list[bytes | Oversized]:
        if self._skip:
            taken = min(self._skip, len(data))
            self._skip -= taken
            data = data[taken:]
        self._buffer += data
        out: list[bytes | Oversized] = []
        while len(self._buffer) >= HEADER.size and not self._skip:
            (length,) = HEADER.unpack_from(self._buffer)
            if length > self.max_frame_bytes:
                out.append(Oversized(length))
                held = len(self._buffer) - HEADER.size
                self._skip = max(0, length - held)
                del self._buffer[: HEADER.size + min(length, held)]
                continue
            if len(self._buffer) < HEADER.size + length:
                break
            out.append(bytes(self._buffer[HEADER.size : HEADER.size + length]))
            del self._buffer[: HEADER.size + length]
        return out


def parse_message(body: bytes) -> dict[str, Any]:
    """The JSON object of a frame; ``WireProtocolError`` when it is not one."""
    try:
        message = orjson.loads(body)
    except orjson.JSONDecodeError as err:
        raise WireProtocolError(f"not JSON: {err}") from err
    if not isinstance(message, dict):
        raise WireProtocolError(f"a frame must hold a JSON object, got {type(message).__name__}")
    return message


def message_kind(message: dict[str, Any]) -> str:
    """The kind of a client's message; ``WireProtocolError`` when it is not one we know."""
    kind = message.get("kind")
    if kind not in CLIENT_KINDS:
        raise WireProtocolError(f"unknown kind {_shown(kind)} (expected one of {CLIENT_KINDS})")
    return str(kind)


@dataclass(frozen=True, slots=True)
class Hello:
    """Who a client is: the session its cycles are logged under."""

    robot_id: str
    period_ns: int
    clock: str
    software_version: str
    policy_version: str
    profile: str
    recordings: tuple[str, ...] = ()
    """The robot's sensor recordings (rosbag2 folders, MCAP files) by their path on this
    machine: declared in its log and sealed as they grow (profile 1.4)."""


def parse_hello(message: dict[str, Any]) -> Hello:
    """Check a hello; ``WireProtocolError`` naming the first thing wrong."""
    _no_unknown(message, _HELLO_FIELDS, "hello")
    version = message.get("protocol")
    if version != PROTOCOL_VERSION or isinstance(version, bool):
        raise WireProtocolError(
            f"protocol version {_shown(version)} is not spoken here (this recorder speaks "
            f"version {PROTOCOL_VERSION})"
        )
    robot_id = _text(message, "robot_id", required=True)
    if not _ROBOT_ID.fullmatch(robot_id):
        raise WireProtocolError(
            f"robot_id must be a simple name (letters, digits, _.-): {_shown(robot_id)}"
        )
    period_ns = _integer(message, "period_ns", MIN_PERIOD_NS, INT64_MAX, required=True)
    profile = _text(message, "profile") or "1"
    if not _PROFILE.fullmatch(profile):
        raise WireProtocolError(f"profile {_shown(profile)}: this recorder writes profile 1.x")
    assert period_ns is not None  # required=True
    return Hello(
        robot_id=robot_id,
        period_ns=period_ns,
        clock=_text(message, "clock") or "system",
        software_version=_text(message, "software_version"),
        policy_version=_text(message, "policy_version"),
        profile=profile,
        recordings=_recordings(message.get("recordings")),
    )


def _recordings(value: object) -> tuple[str, ...]:
    """A hello's ``recordings``: a list of at most ``MAX_RECORDINGS`` non-empty paths."""
    if value is None:
        return ()
    if not isinstance(value, list) or len(value) > MAX_RECORDINGS:
        raise WireProtocolError(f"recordings must be a list of at most {MAX_RECORDINGS} paths")
    if not all(isinstance(p, str) and 0 < len(p) <= 4096 and "\x00" not in p for p in value):
        raise WireProtocolError("recordings must be paths (non-empty strings)")
    return tuple(value)


@dataclass(frozen=True, slots=True)
class SensorMessage:
    """One reading of a cycle message: its topic, its JSON value, and its log time."""

    topic: str
    data: Any
    log_time_ns: int | None


@dataclass(frozen=True, slots=True)
class CycleMessage:
    """One decision cycle as a client sent it; its layers are still unchecked dicts."""

    seq: int | None
    dropped: int
    t_ns: int
    layers: dict[str, Any]
    sensors: tuple[SensorMessage, ...]


def parse_cycle(message: dict[str, Any]) -> CycleMessage:
    """Check a cycle message's own fields (not the records in it, which the logger checks)."""
    _no_unknown(message, _CYCLE_FIELDS, "cycle")
    seq = _integer(message, "seq", 0, INT64_MAX)
    dropped = _integer(message, "dropped", 0, MAX_DECLARED_DROPS) or 0
    t_ns = _integer(message, "t_ns", 0, INT64_MAX, required=True)
    assert t_ns is not None  # required=True
    layers: dict[str, Any] = {}
    for name in LAYERS:
        value = message.get(name)
        if value is None:
            continue
        if not isinstance(value, dict):
            raise WireProtocolError(f"{name} must be a JSON object or null")
        layers[name] = value
    raw = message.get("sensors") or []
    if not isinstance(raw, list) or len(raw) > MAX_SENSORS:
        raise WireProtocolError(f"sensors must be a list of at most {MAX_SENSORS} readings")
    sensors = tuple(_sensor(item, number) for number, item in enumerate(raw))
    return CycleMessage(seq, dropped, t_ns, layers, sensors)


def _sensor(item: Any, number: int) -> SensorMessage:
    where = f"sensors[{number}]"
    if not isinstance(item, dict):
        raise WireProtocolError(f"{where} must be a JSON object")
    _no_unknown(item, _SENSOR_FIELDS, where)
    if "data" not in item:
        raise WireProtocolError(f"{where}: data is missing")
    topic = _text(item, "topic", required=True, where=where)
    log_time_ns = _integer(item, "log_time_ns", 0, INT64_MAX, where=where)
    return SensorMessage(topic, item["data"], log_time_ns)


def _no_unknown(message: dict[str, Any], known: frozenset[str], what: str) -> None:
    unknown = sorted(set(message) - known)
    if unknown:
        raise WireProtocolError(f"{what}: unknown field {_shown(unknown[0])}")


def _text(message: dict[str, Any], key: str, *, required: bool = False, where: str = "") -> str:
    value = message.get(key)
    name = f"{where}: {key}" if where else key
    if value is None and not required:
        return ""
    if not isinstance(value, str) or (required and not value) or len(value) > _MAX_TEXT:
        raise WireProtocolError(f"{name} must be a string of 1 to {_MAX_TEXT} characters")
    return value


def _integer(
    message: dict[str, Any],
    key: str,
    low: int,
    high: int,
    *,
    required: bool = False,
    where: str = "",
) -> int | None:
    value = message.get(key)
    name = f"{where}: {key}" if where else key
    if value is None and not required:
        return None
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise WireProtocolError(f"{name} must be an integer from {low} to {high}")
    return value


def _shown(value: Any) -> str:
    """A value quoted in a reason, cut short: a hostile client's text stays one short line."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
