"""One client's conversation with the recorder, on its own thread.

The client never waits for the recorder: cycles flow one way, and what goes back (an error
naming a refused frame, a stats or flush answer) is queued in a bounded outbox and sent when
the socket takes it. A client that never reads its replies cannot stall the recorder: past
the outbox's bound, replies are dropped and counted. A frame over the limit, or one that is
not a message of the protocol, is refused with its reason, counted, and logged as one line
(the first few per connection; the rest only counted, so a hostile client cannot flood the
recorder's log); the connection goes on, and no other robot notices.
"""

from __future__ import annotations

import logging
import selectors
import socket
import threading
from dataclasses import dataclass, field
from typing import Any

from trace_runtime.errors import RecordError, TraceError, UsageError, WireProtocolError
from trace_runtime.recorder.protocol import (
    PROTOCOL_VERSION,
    FrameReader,
    Oversized,
    encode_frame,
    message_kind,
    parse_cycle,
    parse_hello,
    parse_message,
)
from trace_runtime.recorder.robots import RobotLog, Robots

__all__ = ["Connection", "RecorderCounters"]

log = logging.getLogger("trace_runtime.recorder")

_RECV_BYTES = 256 * 1024
_OUTBOX_BYTES = 256 * 1024
_LOGGED_REFUSALS = 5  # per connection; the rest are counted only
_POLL_S = 0.1  # how soon a connection notices the recorder stopping


@dataclass(slots=True)
class RecorderCounters:
    """What the recorder counted across all connections (the ``recorder`` part of stats)."""

    connections: int = 0
    refused_connections: int = 0
    refused_frames: int = 0
    replies_dropped: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, name: str, n: int = 1) -> None:
        with self._lock:
            setattr(self, name, getattr(self, name) + n)

    def as_dict(self) -> dict[str, int]:
        with self._lock:
            return {
                "connections": self.connections,
                "refused_connections": self.refused_connections,
                "refused_frames": self.refused_frames,
                "replies_dropped": self.replies_dropped,
            }


class Connection:
    """Reads one client's frames, writes its cycles through its robot's logger, and
    answers; ends at ``bye``, end of stream, or when ``stopping`` is set."""

    def __init__(
        self,
        sock: socket.socket,
        *,
        peer: str,
        robots: Robots,
        counters: RecorderCounters,
        stopping: threading.Event,
        max_frame_bytes: int,
    ) -> None:
        self.sock = sock
        self.peer = peer
        self.robots = robots
        self.counters = counters
        self.stopping = stopping
        self.robot: RobotLog | None = None
        self._reader = FrameReader(max_frame_bytes)
        self._outbox = bytearray()
        self._logged = 0
        self._over = False  # bye, or the client refused: reply, then hang up

    def run(self) -> None:
        try:
            self._serve()
            self._drain_outbox()
        except OSError as err:  # the client went away mid-reply: its cycles so far are kept
            log.info("%s: connection lost: %s", self._who(), err)
        finally:
            if self.robot is not None:
                self.robots.release(self.robot)
            self.sock.close()

    def _serve(self) -> None:
        self.sock.setblocking(False)
        with selectors.DefaultSelector() as selector:
            selector.register(self.sock, selectors.EVENT_READ)
            while not self.stopping.is_set():
                wanted = selectors.EVENT_READ | (selectors.EVENT_WRITE if self._outbox else 0)
                selector.modify(self.sock, wanted)
                for _, events in selector.select(_POLL_S):
                    if events & selectors.EVENT_WRITE:
                        self._send_some()
                    if events & selectors.EVENT_READ and not self._read():
                        self._ended_midway()
                        return
                    if self._over:
                        return
            self._reply({"kind": "bye", "reason": "the recorder is stopping"})

    def _read(self) -> bool:
        """Take what the socket has; False at the end of the stream."""
        try:
            data = self.sock.recv(_RECV_BYTES)
        except BlockingIOError:
            return True
        if not data:
            return False
        for frame in self._reader.feed(data):
            self._handle(frame)
            if self._over:
                break  # what follows a bye or a refusal is not read
        return True

    def _ended_midway(self) -> None:
        if self._reader.pending:
            log.info("%s: stream ended inside a frame (%d bytes dropped)", self._who(),
                     self._reader.pending)  # fmt: skip

    def _handle(self, frame: bytes | Oversized) -> None:
        seq: Any = None
        try:
            if isinstance(frame, Oversized):
                raise WireProtocolError(
                    f"frame of {frame.length} bytes is over the limit of "
                    f"{self._reader.max_frame_bytes} bytes (skipped)"
                )
            message = parse_message(frame)
            seq = message.get("seq")
            self._dispatch(message)
        except (WireProtocolError, RecordError, UsageError) as err:
            self._refuse_frame(seq, str(err))

    def _dispatch(self, message: dict[str, Any]) -> None:
        kind = message_kind(message)
        if kind == "hello":
            self._hello(message)
            return
        robot = self.robot
        if robot is None:
            self._refuse_client(f"a {kind} before hello: a client begins with hello")
        elif kind == "cycle":
            robot.write(parse_cycle(message))
        elif kind == "stats":
            counters = {"robot": robot.counters(), "recorder": self.counters.as_dict()}
            self._reply({"kind": "stats", "seq": message.get("seq"), **counters})
        elif kind == "flush":
            done = robot.logger.flush()
            self._reply({"kind": "flushed", "seq": message.get("seq"), "ok": done})
        else:  # bye: the robot's segment is finished before the client is told
            self.robot = None
            self.robots.release(robot)
            self._reply({"kind": "bye"})
            self._over = True

    def _hello(self, message: dict[str, Any]) -> None:
        if self.robot is not None:
            raise WireProtocolError("hello sent twice on one connection")
        try:
            hello = parse_hello(message)
            self.robot = self.robots.claim(hello)
        except (TraceError, OSError) as err:  # OSError: the root cannot be written
            self._refuse_client(str(err))
            return
        self._reply(
            {
                "kind": "welcome",
                "protocol": PROTOCOL_VERSION,
                "robot_id": hello.robot_id,
                "max_frame_bytes": self._reader.max_frame_bytes,
            }
        )
        log.info("%s: robot %s connected", self.peer, hello.robot_id)

    def _refuse_client(self, reason: str) -> None:
        self.counters.add("refused_connections")
        log.warning("%s: refused: %s", self._who(), reason)
        self._reply({"kind": "refused", "reason": reason})
        self._over = True

    def _refuse_frame(self, seq: Any, reason: str) -> None:
        self.counters.add("refused_frames")
        if self.robot is not None:
            self.robot.refused += 1
        if not isinstance(seq, int) or isinstance(seq, bool):
            seq = None
        self._reply({"kind": "error", "seq": seq, "reason": reason})
        self._logged += 1
        if self._logged <= _LOGGED_REFUSALS:
            log.warning("%s: frame refused: %s", self._who(), reason)
        if self._logged == _LOGGED_REFUSALS:
            log.warning("%s: further refused frames are counted, not logged", self._who())

    def _reply(self, message: dict[str, Any]) -> None:
        frame = encode_frame(message)
        if len(self._outbox) + len(frame) > _OUTBOX_BYTES:
            self.counters.add("replies_dropped")
            return
        self._outbox += frame
        self._send_some()

    def _send_some(self) -> None:
        try:
            sent = self.sock.send(self._outbox)
        except (BlockingIOError, InterruptedError):
            return
        del self._outbox[:sent]

    def _drain_outbox(self) -> None:
        """The last replies (refused, bye) reach the client if it reads within a moment."""
        try:
            self.sock.settimeout(1.0)
            self.sock.sendall(self._outbox)
        except OSError:
            pass
        self._outbox.clear()

    def _who(self) -> str:
        return f"{self.peer} ({self.robot.hello.robot_id})" if self.robot else self.peer
