"""Clients that break the protocol, against a real ``trace-recorder``: frames crafted by
hand (struct and json, not the recorder's own encoder). Each bad frame is refused with its
reason, counted, and logged as one line; memory stays bounded; the connection, and every
other robot, goes on."""

from __future__ import annotations

import json
import socket
import stat
import struct
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.outside import cli
from tests.trace_runtime.recorder.conftest import RecorderProcess, _pairs
from trace_runtime.errors import UsageError
from trace_runtime.recorder import RemoteLogger

_OPEN: list[socket.socket] = []


@pytest.fixture(autouse=True)
def _close_raw_clients() -> Iterator[None]:
    yield
    while _OPEN:
        _OPEN.pop().close()


class RawClient:
    """A client that writes whatever bytes it is told to."""

    def __init__(self, path: Path) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.connect(str(path))
        self.sock.settimeout(5.0)
        self._buffer = b""
        _OPEN.append(self.sock)

    def send(self, message: Any) -> None:
        body = message if isinstance(message, bytes) else json.dumps(message).encode()
        self.sock.sendall(struct.pack(">I", len(body)) + body)

    def hello(self, robot_id: str) -> dict[str, Any]:
        self.send({"kind": "hello", "protocol": 1, "robot_id": robot_id, "period_ns": 10_000_000})
        return self.reply()

    def reply(self) -> dict[str, Any]:
        while len(self._buffer) < 4 or len(self._buffer) < 4 + self._length():
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("closed")
            self._buffer += data
        body = self._buffer[4 : 4 + self._length()]
        self._buffer = self._buffer[4 + len(body) :]
        answer: dict[str, Any] = json.loads(body)
        return answer

    def _length(self) -> int:
        (length,) = struct.unpack(">I", self._buffer[:4])
        return int(length)


def _cycle(seq: int, t_ns: int, **fields: Any) -> dict[str, Any]:
    action = {"command": "GO", "rationale": {"text": "clear"}, "alternatives": []}
    return {"kind": "cycle", "seq": seq, "t_ns": t_ns, "action": action, **fields}


def _rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError("no VmRSS")


def test_bad_frames_are_refused_counted_and_logged_while_another_robot_runs(
    recorder: RecorderProcess, cpp_robot: Path
) -> None:
    command = [str(cpp_robot), "--socket", str(recorder.socket), "--robot-id", "good"]
    command += ["--cycles", "300", "--hz", "200", "--sim-time"]
    good = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)

    bad = RawClient(recorder.socket)
    assert bad.hello("hostile")["kind"] == "welcome"
    bad.send(_cycle(0, 1_000))  # a good cycle first
    hostile: list[tuple[Any, str]] = [
        (b"{not json", "not JSON"),
        (b"[1, 2]", "a JSON object"),
        ({"kind": "launch", "seq": 1}, "unknown kind"),
        (_cycle(2, 2_000, colour="red"), "unknown field 'colour'"),
        (_cycle(3, 3_000, perception={"entities": [{"id": "x"}]}), "Perception"),
        (_cycle(4, -5), "t_ns"),  # a negative time (one going back is a clock step)
        (b"[" * 100_000 + b"]" * 100_000, "not JSON"),  # nested past the parser's depth
    ]
    for message, _ in hostile:
        bad.send(message)
    for message, needle in hostile:
        answer = bad.reply()
        assert answer["kind"] == "error", answer
        assert needle in answer["reason"], (needle, answer)
        expected = message.get("seq") if isinstance(message, dict) else None
        assert answer["seq"] == expected

    # An oversized frame: 4 GiB announced, 64 MiB sent; skipped as it arrives, not kept.
    pid = recorder.proc.pid if recorder.proc else 0
    before = _rss_kb(pid)
    bad.sock.sendall(struct.pack(">I", 0xFFFFFFFF))
    chunk = b"\0" * (1 << 20)
    for _ in range(64):
        bad.sock.sendall(chunk)
    answer = bad.reply()
    assert "over the limit" in answer["reason"] and answer["seq"] is None
    assert _rss_kb(pid) - before < 16 * 1024
    bad.sock.close()  # mid-frame: the recorder drops the rest and closes the robot's logger

    last = _pairs(good.communicate(timeout=60)[0].strip().splitlines()[-1])
    assert last["sent"] == 300 and last["dropped"] == 0
    time.sleep(0.3)
    code, stderr = recorder.stop()
    assert code == 0, stderr
    assert "Traceback" not in stderr
    refused = [line for line in stderr.splitlines() if "frame refused" in line]
    assert len(refused) == 5  # the first five, then one line saying the rest are counted
    assert "further refused frames are counted, not logged" in stderr

    report = json.loads(cli("verify", recorder.root, "--json").stdout)
    assert report["ok"] and not report["findings"]
    robots = {r["robot_id"]: r for r in report["robots"]}
    assert robots["good"]["cycles_valid"] == 300 and robots["good"]["declared_dropped"] == 0
    # The hostile robot's one good cycle is logged, and nothing of its refused ones.
    assert robots["hostile"]["cycles_valid"] == 1


def test_a_client_must_begin_with_hello(recorder: RecorderProcess) -> None:
    raw = RawClient(recorder.socket)
    raw.send(_cycle(0, 1_000))
    answer = raw.reply()
    assert answer["kind"] == "refused" and "before hello" in answer["reason"]
    with pytest.raises(ConnectionError):
        raw.reply()  # and the connection is closed


@pytest.mark.parametrize(
    ("hello", "needle"),
    [
        ({"protocol": 2}, "protocol version 2"),
        ({"robot_id": "../etc"}, "simple name"),
        ({"period_ns": 10}, "period_ns"),
        ({"profile": "2.0"}, "profile 1.x"),
    ],
)
def test_a_bad_hello_is_refused_with_its_reason(
    recorder: RecorderProcess, hello: dict[str, Any], needle: str
) -> None:
    raw = RawClient(recorder.socket)
    base = {"kind": "hello", "protocol": 1, "robot_id": "r1", "period_ns": 10_000_000}
    raw.send(base | hello)
    answer = raw.reply()
    assert answer["kind"] == "refused" and needle in answer["reason"], answer


def test_a_second_client_claiming_a_connected_robot_id_is_refused(
    recorder: RecorderProcess,
) -> None:
    with RemoteLogger(recorder.socket, robot_id="amr-1", period_s=0.01) as first:
        with pytest.raises(UsageError, match="already connected"):
            RemoteLogger(recorder.socket, robot_id="amr-1", period_s=0.01)
        raw = RawClient(recorder.socket)
        answer = raw.hello("amr-1")
        assert answer["kind"] == "refused" and "already connected" in answer["reason"]
        first.log_cycle(1_000, action={"command": "GO", "rationale": {"text": "ok"}})
        assert first.flush()
        assert first.stats.sent == 1 and first.stats.refused == 0


def test_the_socket_is_open_to_its_group_only(recorder: RecorderProcess) -> None:
    mode = recorder.socket.stat().st_mode
    assert stat.S_ISSOCK(mode)
    assert stat.S_IMODE(mode) == 0o660
