"""``trace-audit tail --foxglove``: a robot logging in one process, ``tail`` serving it live
in another, and a client speaking the Foxglove WebSocket protocol in the test: it is told the
channels (``serverInfo``, ``advertise``), subscribes, and gets the scene and the decision
changes as binary message-data frames while the robot logs.

The SDK's server (foxglove-sdk 0.30.3) names the protocol ``foxglove.sdk.v1`` in the
WebSocket handshake and refuses a client that offers only the older name,
``foxglove.websocket.v1``; the client here offers both, as Foxglove does. It is tornado's
WebSocket client (installed with the fleet extra's dask)."""

from __future__ import annotations

import asyncio
import base64
import gc
import json
import queue
import signal
import struct
import threading
import time
import warnings
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from tests.trace_audit.foxglove.test_foxglove_decoded import _decoder
from tests.trace_audit.test_tail import _Lines, _log, _robot, _tail

pytest.importorskip("foxglove")
pytest.importorskip("google.protobuf")
websocket = pytest.importorskip("tornado.websocket")

SUBPROTOCOL = "foxglove.sdk.v1"
OLD_SUBPROTOCOL = "foxglove.websocket.v1"
MESSAGE_DATA = 0x01
WITHIN_S = 30.0


class _Stderr:
    """A process's stderr lines, read on a thread (the live view prints its address there)."""

    def __init__(self, stream: Any) -> None:
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        self.reader = threading.Thread(target=lambda: [self.lines.put(x) for x in stream])
        self.reader.start()

    def until(self, needle: str, within_s: float) -> str:
        deadline = time.monotonic() + within_s
        while True:
            try:
                line = self.lines.get(timeout=max(deadline - time.monotonic(), 0.001))
            except queue.Empty:
                pytest.fail(f"no stderr line with {needle!r} within {within_s} s: {self.seen}")
            self.seen.append(line)
            if needle in line:
                return line


async def _watch(url: str, robot: Any) -> tuple[dict[str, Any], list[dict[str, Any]], dict]:
    """Connect, read serverInfo and the advertised channels, subscribe to every channel,
    and read message data (the robot logging meanwhile) until the scene and the decision
    channels have each sent something; (serverInfo, channels, messages by topic)."""
    with pytest.raises(Exception, match="400"):
        await websocket.websocket_connect(url, subprotocols=[OLD_SUBPROTOCOL])
    conn = await websocket.websocket_connect(url, subprotocols=[OLD_SUBPROTOCOL, SUBPROTOCOL])
    assert conn.selected_subprotocol == SUBPROTOCOL
    info: dict[str, Any] = {}
    channels: dict[int, dict[str, Any]] = {}
    got: dict[str, list[tuple[int, bytes]]] = {}
    by_subscription: dict[int, str] = {}
    deadline = time.monotonic() + WITHIN_S
    last_logged = 0.0
    while time.monotonic() < deadline:
        try:
            frame = await asyncio.wait_for(conn.read_message(), timeout=0.5)
        except TimeoutError:
            frame = ""
        if frame is None:
            pytest.fail("the server closed the connection")
        if isinstance(frame, bytes):
            assert frame[0] == MESSAGE_DATA, frame[:1]
            subscription, t_ns = struct.unpack_from("<IQ", frame, 1)
            got.setdefault(by_subscription[subscription], []).append((t_ns, frame[13:]))
        elif frame:
            op = json.loads(frame)
            if op["op"] == "serverInfo":
                info = op
            elif op["op"] == "advertise":
                fresh = [c for c in op["channels"] if c["id"] not in channels]
                channels.update({c["id"]: c for c in fresh})
                subscriptions = []
                for channel in fresh:
                    sub = len(by_subscription) + 1
                    by_subscription[sub] = channel["topic"]
                    subscriptions.append({"id": sub, "channelId": channel["id"]})
                await conn.write_message(
                    json.dumps({"op": "subscribe", "subscriptions": subscriptions})
                )
        if by_subscription and {"/foxglove/scene", "/foxglove/decisions"} <= set(got):
            break
        if by_subscription and time.monotonic() - last_logged > 0.3:
            _log(robot, 3)  # the command changes every third cycle: a decision change
            last_logged = time.monotonic()
    conn.close()
    await asyncio.sleep(0.2)  # the close handshake
    return info, list(channels.values()), got


def test_tail_serves_the_robot_live_to_a_foxglove_websocket_client(tmp_path: Path) -> None:
    root = tmp_path / "root"
    with _robot(root) as robot:
        _log(robot, 2)
        with _tail(root, "--foxglove", "--port", "0") as follower:
            assert follower.stderr is not None
            err = _Stderr(follower.stderr)
            said = err.until("ws://127.0.0.1:", WITHIN_S)
            url = said.split(" on ", 1)[1].split()[0]
            out = _Lines(follower)
            out.until("r_000000.mcap live", WITHIN_S)  # it follows, and prints as tail does
            info, channels, got = asyncio.run(_watch(url, robot))
            with warnings.catch_warnings():
                # tornado leaves the socket of the refused handshake to the garbage
                # collector: collected here, it cannot warn inside a later test
                warnings.simplefilter("ignore", ResourceWarning)
                gc.collect()
            follower.send_signal(signal.SIGINT)
            assert follower.wait(10) == 0
            out.reader.join(10)
            err.reader.join(10)
    assert "Traceback" not in "".join(err.seen), err.seen
    assert info["name"] == "trace-audit tail"
    topics = {c["topic"]: c for c in channels}
    expected = {
        "/foxglove/scene": ("foxglove.SceneUpdate", "protobuf"),
        "/foxglove/robot_pose": ("foxglove.PoseInFrame", "protobuf"),
        "/foxglove/decisions": ("foxglove.Log", "protobuf"),
        "/foxglove/factors": ("factors", "json"),
        "/foxglove/actuators": ("actuators", "json"),
        "/trace/action": ("trace.Action", "json"),
        "/trace/seal": ("trace.Seal", "json"),
    }
    for topic, (schema_name, encoding) in expected.items():
        assert topic in topics, sorted(topics)
        assert topics[topic]["encoding"] == encoding, topics[topic]
        assert topics[topic]["schemaName"] == schema_name

    def decode(topic: str, data: bytes) -> Any:
        channel = topics[topic]
        schema = SimpleNamespace(
            name=channel["schemaName"], data=base64.b64decode(channel["schema"])
        )
        return _decoder(schema)(data)

    for t_ns, data in got["/foxglove/scene"]:
        update = decode("/foxglove/scene", data)
        assert update.deletions and update.deletions[0].timestamp.nanos == t_ns % 10**9
    for t_ns, data in got["/foxglove/decisions"]:
        entry = decode("/foxglove/decisions", data)
        assert entry.message.startswith(f"cycle {entry.line}: ") and " -> " in entry.message
        assert entry.name == "r" and t_ns == entry.line * 100_000_000
    while not out.lines.empty():  # what tail printed after the lines waited for
        out.seen.append(out.lines.get())
    shown = "\n".join(out.seen)
    for _t_ns, data in got["/foxglove/decisions"]:
        cycle = decode("/foxglove/decisions", data).line
        assert f"cycle {cycle} " in shown  # the change tail printed is the one it sent


def test_a_taken_port_is_a_usage_error_in_one_line(tmp_path: Path) -> None:
    from tests.outside import cli

    with _robot(tmp_path / "root") as robot:
        _log(robot, 1)
        with _tail(tmp_path / "root", "--foxglove", "--port", "0") as first:
            assert first.stderr is not None
            err = _Stderr(first.stderr)
            port = err.until("ws://127.0.0.1:", WITHIN_S).split("127.0.0.1:")[1].split()[0]
            second = cli("tail", tmp_path / "root", "--foxglove", "--port", port)
            first.send_signal(signal.SIGINT)
            assert first.wait(10) == 0
            err.reader.join(10)
    assert second.returncode == 2, second.stderr
    assert second.stderr.count("\n") == 1 and "Address already in use" in second.stderr


def test_a_root_of_several_robots_needs_robot_for_the_live_view(tmp_path: Path) -> None:
    from tests.outside import cli
    from tests.trace_audit.conftest import write_log

    root = tmp_path / "root"
    write_log(root, robot_id="amr-1")
    write_log(root, robot_id="amr-2")
    done = cli("tail", root, "--foxglove", "--port", "0")
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "choose one with --robot" in done.stderr
