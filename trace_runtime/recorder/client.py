"""``RemoteLogger``: ``AuditLogger``'s API, writing through a recorder (``trace-recorder``)
instead of in this process.

For a Python robot that cannot hold the log itself (a process without write access to the
log root, many short-lived processes feeding one chain per robot id) and as the reference
client of the wire protocol (schemas/PROFILE.md section 13). The control thread only keeps
references: ``commit()`` appends the cycle to a bounded queue and returns. A sender thread
turns cycles into frames and sends them; a reader thread takes the recorder's answers. The
control loop never waits for the recorder: a full queue or a lost connection drops the
cycle and counts it (``stats``), the next cycle sent declares the drops, and the sender
reconnects with a growing pause (50 ms to 1 s). Records are checked by the recorder, with
the logger's own models: a refused cycle comes back as an error, counted in
``stats.refused`` and logged once, never raised into the loop.
"""

from __future__ import annotations

import contextlib
import logging
import re
import socket
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

import orjson
from pydantic import BaseModel

from trace_runtime.errors import RecordError, UsageError
from trace_runtime.recorder.protocol import (
    MAX_DECLARED_DROPS,
    PROTOCOL_VERSION,
    FrameReader,
    encode_frame,
)
from trace_runtime.recorder.remote_cycle import RemoteCycle, RemoteStats
from trace_runtime.session import MIN_PERIOD_NS

__all__ = ["RemoteCycle", "RemoteLogger", "RemoteStats"]

log = logging.getLogger("trace_runtime.recorder")

Address = str | Path | tuple[str, int]
"""A Unix socket's path, or a loopback (host, port)."""

_BACKOFF_S = (0.05, 1.0)  # first and longest pause between connection attempts


class _Request:
    """A question to the recorder (flush, stats, bye) and the answer its thread waits for."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.answered = threading.Event()
        self.answer: dict[str, Any] = {}


class RemoteLogger:
    """Writes a robot's decision cycles through a recorder at ``address``.

    Waits up to ``connect_timeout_s`` for the recorder's welcome, so the first cycles are
    not dropped; an unreachable recorder is retried in the background (cycles are dropped
    and counted meanwhile). A recorder that refuses this robot (another client holds its
    id, a bad period) raises ``UsageError`` with the recorder's reason.
    """

    def __init__(
        self,
        address: Address,
        *,
        robot_id: str,
        period_s: float = 0.1,
        software_version: str = "",
        policy_version: str = "",
        clock: str = "system",
        queue_cycles: int = 256,
        connect_timeout_s: float = 2.0,
        recordings: tuple[str | Path, ...] = (),
    ) -> None:
        if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", robot_id):
            raise UsageError(f"robot_id must be a simple name (letters, digits, _.-): {robot_id!r}")
        if not period_s * 1e9 >= MIN_PERIOD_NS:  # also refuses NaN
            raise UsageError(f"period_s must be at least {MIN_PERIOD_NS / 1e9:g} s")
        self.address = address
        self.robot_id = robot_id
        self.stats = RemoteStats()
        self._hello = {
            "kind": "hello",
            "protocol": PROTOCOL_VERSION,
            "robot_id": robot_id,
            "period_ns": round(period_s * 1e9),
            "clock": clock,
            "software_version": software_version,
            "policy_version": policy_version,
            "profile": "1",
        }
        if recordings:  # declared and sealed by the recorder, as LoggerConfig.recordings
            self._hello["recordings"] = [str(Path(p).absolute()) for p in recordings]
        self._capacity = queue_cycles
        self._timeout_s = connect_timeout_s
        self._queue: deque[RemoteCycle | _Request] = deque()
        self._ready = threading.Event()
        self._connected = False  # written by the sender, read by the control thread
        self._closed = False
        self._open: RemoteCycle | None = None
        self._next = 0
        self._declared = 0  # drops already carried by a sent cycle (sender thread only)
        self._sock: socket.socket | None = None
        self._pending: dict[int, _Request] = {}
        self._request_seq = 0
        self._first = threading.Event()
        self._refusal = ""
        self._noted: set[str] = set()
        self._sender = threading.Thread(target=self._send_loop, name="trace remote", daemon=True)
        self._sender.start()
        self._first.wait(connect_timeout_s)
        if self._refusal:
            self._closed = True
            self._ready.set()
            raise UsageError(f"the recorder at {address} refused {robot_id}: {self._refusal}")

    # --- control-thread API -------------------------------------------------------------

    def cycle(self, t_ns: int | None = None) -> RemoteCycle:
        """Begin the next decision cycle at ``t_ns`` (default: now, wall clock)."""
        if self._closed:
            raise UsageError("the logger is closed")
        if self._open is not None and not self._open._committed:
            raise UsageError(f"cycle {self._open.cycle} was begun but not committed")
        if t_ns is None:
            t_ns = time.time_ns()
        elif t_ns < 0:
            raise RecordError(f"cycle time {t_ns} ns is negative (PROFILE section 4)")
        builder = RemoteCycle(self, self._next, t_ns)
        self._next += 1
        self._open = builder
        return builder

    begin = cycle

    def log_cycle(
        self,
        t_ns: int | None = None,
        *,
        perception: Any = None,
        belief: Any = None,
        action: Any = None,
        execution: Any = None,
    ) -> int:
        """Log a whole cycle in one call; return its number on this client."""
        with self.cycle(t_ns) as c:
            for add, record in (
                (c.perception, perception),
                (c.belief, belief),
                (c.action, action),
                (c.execution, execution),
            ):
                if record is not None:
                    add(record)
        return c.cycle

    def _commit(self, builder: RemoteCycle) -> None:
        self.stats.committed += 1
        if not self._connected:
            self.stats.dropped_disconnected += 1
        elif len(self._queue) >= self._capacity:
            self.stats.dropped_queue_full += 1
        else:
            self._queue.append(builder)
            self._ready.set()

    def flush(self, timeout_s: float = 5.0) -> bool:
        """Wait until the recorder has written every cycle sent so far; True if it did."""
        answer = self._ask("flush", timeout_s)
        return bool(answer.get("ok"))

    def recorder_stats(self, timeout_s: float = 2.0) -> dict[str, Any]:
        """The recorder's counters for this robot and its own (empty when unanswered)."""
        return self._ask("stats", timeout_s)

    def close(self, timeout_s: float | None = 5.0) -> None:
        """Send what is queued, say bye (the recorder finishes the robot's segment), and
        stop the threads, waiting at most ``timeout_s``. Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._ask("bye", timeout_s)
        self._sender.join(timeout_s)

    def __enter__(self) -> RemoteLogger:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _ask(self, kind: str, timeout_s: float | None) -> dict[str, Any]:
        request = _Request(kind)
        if kind != "bye" and not self._connected:
            return {}
        self._queue.append(request)  # requests pass the bound: they are few and small
        self._ready.set()
        request.answered.wait(timeout_s)
        return request.answer

    # --- the sender thread --------------------------------------------------------------

    def _send_loop(self) -> None:
        pause = _BACKOFF_S[0]
        while True:
            if self._sock is not None and not self._connected:  # the reader saw the end
                self._lost("the recorder closed the connection")
            if self._sock is None:
                if self._closed and not self._queue:
                    return
                if not self._connect():
                    self._drop_queued()
                    if self._closed:
                        return
                    time.sleep(pause)
                    pause = min(pause * 2, _BACKOFF_S[1])
                    continue
                pause = _BACKOFF_S[0]
            self._ready.wait(0.1)
            self._ready.clear()
            while self._queue and self._sock is not None:
                item = self._queue.popleft()
                if isinstance(item, _Request):
                    if self._request(item):
                        return
                else:
                    self._send_cycle(item)

    def _send_cycle(self, item: RemoteCycle) -> None:
        declared = min(self.stats.dropped - self._declared, MAX_DECLARED_DROPS)
        message: dict[str, Any] = {
            "kind": "cycle",
            "seq": item.cycle,
            "dropped": declared,
            "t_ns": item.t_ns,
            **item._layers,
        }
        if item._sensors:
            message["sensors"] = [
                {"topic": topic, "data": data, "log_time_ns": log_time}
                for topic, data, log_time in item._sensors
            ]
        try:
            frame = encode_frame(message, default=_plain)
        except TypeError as err:  # a record orjson cannot write: the robot's bug, not I/O
            self._note_refused(f"cycle {item.cycle} cannot be sent: {err}")
            return
        if self._send(frame):
            self._declared += declared
            self.stats.sent += 1
        else:
            self.stats.dropped_unsent += 1

    def _request(self, request: _Request) -> bool:
        """Send a flush, stats or bye; True when the sender is to stop (bye)."""
        self._request_seq += 1
        self._pending[self._request_seq] = request
        if request.kind == "bye":
            self._send(encode_frame({"kind": "bye"}))
            request.answered.wait(self._timeout_s)
            self._disconnect()
            request.answered.set()
            return True
        if not self._send(encode_frame({"kind": request.kind, "seq": self._request_seq})):
            request.answered.set()
        return False

    def _send(self, frame: bytes) -> bool:
        sock = self._sock
        if sock is None:
            return False
        try:
            sock.sendall(frame)
        except OSError as err:
            self._lost(f"send failed: {err}")
            return False
        return True

    def _connect(self) -> bool:
        """Connect and say hello; True when welcomed (the reader thread then runs)."""
        where: str | tuple[str, int]
        if isinstance(self.address, tuple):
            where = self.address
            family = socket.AF_INET6 if ":" in where[0] else socket.AF_INET
        else:
            where, family = str(self.address), socket.AF_UNIX
        sock = socket.socket(family, socket.SOCK_STREAM)
        reader = FrameReader()
        try:
            sock.settimeout(self._timeout_s)
            sock.connect(where)
            sock.sendall(encode_frame(self._hello))
            answer = _first_answer(sock, reader)
        except OSError as err:
            sock.close()
            self._note_once("connect", f"recorder at {self.address} unreachable: {err}")
            return False
        if answer.get("kind") != "welcome":
            sock.close()
            self._refusal = str(answer.get("reason") or "no welcome")
            self._note_once("refused", f"recorder refused {self.robot_id}: {self._refusal}")
            self._first.set()
            return False
        sock.settimeout(None)
        self._sock = sock
        self._refusal = ""
        self.stats.connects += 1
        self._connected = True
        self._first.set()
        threading.Thread(
            target=self._read_loop, args=(sock, reader), name="trace remote reader", daemon=True
        ).start()
        return True

    def _drop_queued(self) -> None:
        while self._queue:
            item = self._queue.popleft()
            if isinstance(item, _Request):
                item.answered.set()
            else:
                self.stats.dropped_unsent += 1

    def _lost(self, reason: str) -> None:
        if self._sock is not None:
            self._note_once("lost", f"connection to the recorder lost: {reason}")
            self._disconnect()

    def _disconnect(self) -> None:
        self._connected = False
        sock, self._sock = self._sock, None
        if sock is not None:
            with contextlib.suppress(OSError):  # already shut by the other side
                sock.shutdown(socket.SHUT_RDWR)
            sock.close()
        for request in self._pending.values():
            request.answered.set()
        self._pending.clear()

    # --- the reader thread --------------------------------------------------------------

    def _read_loop(self, sock: socket.socket, reader: FrameReader) -> None:
        while True:
            try:
                data = sock.recv(65536)
            except OSError:
                data = b""
            if not data:
                self._connected = False  # the sender notices at its next send
                if self._sock is sock:
                    self._ready.set()
                return
            for frame in reader.feed(data):
                try:
                    message = orjson.loads(frame) if isinstance(frame, bytes) else None
                except orjson.JSONDecodeError:
                    message = None  # not the recorder's: ignored, as an unknown kind is
                if isinstance(message, dict):
                    self._answer(message)

    def _answer(self, message: dict[str, Any]) -> None:
        kind = message.get("kind")
        if kind == "error":
            self._note_refused(str(message.get("reason")))
            return
        seq = message.get("seq") if kind in ("stats", "flushed") else None
        if kind == "bye":
            pending = list(self._pending.items())  # the sender thread adds to it
            seq = next((s for s, r in pending if r.kind == "bye"), None)
        request = self._pending.pop(seq, None) if isinstance(seq, int) else None
        if request is not None:
            request.answer = message
            request.answered.set()

    def _note_refused(self, reason: str) -> None:
        self.stats.refused += 1
        self.stats.last_error = reason
        self._note_once("error", f"the recorder refused a frame: {reason}")

    def _note_once(self, kind: str, message: str) -> None:
        if kind not in self._noted:
            self._noted.add(kind)
            log.warning("%s (reported once; see RemoteLogger.stats)", message)


def _first_answer(sock: socket.socket, reader: FrameReader) -> dict[str, Any]:
    """The recorder's answer to a hello (within the socket's timeout)."""
    while True:
        data = sock.recv(65536)
        if not data:
            raise ConnectionError("the recorder closed the connection")
        for frame in reader.feed(data):
            if isinstance(frame, bytes):
                answer: dict[str, Any] = orjson.loads(frame)
                return answer


def _plain(value: Any) -> Any:
    """A record model inside a cycle, as the JSON its fields give (``encode_frame``'s
    ``default``: called only for what orjson cannot write itself)."""
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json", by_alias=True)
    raise TypeError(f"{type(value).__name__} is not JSON")
