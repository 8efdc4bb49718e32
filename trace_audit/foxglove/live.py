"""The Foxglove view of a robot, live: ``trace-audit tail --foxglove``.

``LiveView`` runs the SDK's WebSocket server (``foxglove.start_server``, the Foxglove
WebSocket protocol, ``foxglove.websocket.v1``) and sends, for each cycle tail reads, exactly
the messages the export writes for it (``foxglove.view.FoxgloveView``): the scene update, the
robot's pose, the decision change, the factor and actuator numbers; and the cycle's
``/trace/*`` layers and sensor readings as logged (JSON, the logger's schemas). Foxglove
connects to ``ws://HOST:PORT`` (*Open connection → Foxglove WebSocket*) and shows them as
they are written; the layout in ``docs/foxglove-layout.json`` fits both.

Every Foxglove channel is advertised when the server starts, so a client that connects
before the first decision change still sees the decision channel; sensor channels are
advertised as the robot first logs them. The server binds to 127.0.0.1 unless told
otherwise, sends only what is logged after a client subscribes (the SDK keeps no history),
and sheds the oldest messages of a client that reads too slowly (the SDK's bounded
backlog), so a slow viewer never slows the follower. One robot is shown: the one asked for,
or the only robot of the root (or the first to log into an empty root).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from trace_audit.foxglove.view import FoxgloveView, logged_schema, require_sdk, view_channels
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import UsageError
from trace_runtime.reading.segment_files import segment_files_by_robot
from trace_runtime.records import LAYER_TOPICS, TOPIC_SEAL

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "LiveView", "live_robot"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
"""Foxglove's own default for a WebSocket connection."""


def live_robot(root: str | Path, robots: tuple[str, ...]) -> str | None:
    """The robot the live view shows: the first asked for, else the root's only robot (None:
    an empty root, whose first robot to log is shown). Several robots and none asked for is
    a ``UsageError``: one scene, one robot."""
    if robots:
        return robots[0]
    found = sorted(segment_files_by_robot(Path(root)))
    if len(found) > 1:
        raise UsageError(
            f"the live Foxglove view shows one robot; this root has {len(found)} "
            f"({', '.join(found[:5])}{', ...' if len(found) > 5 else ''}): choose one with --robot"
        )
    return found[0] if found else None


class LiveView:
    """A running Foxglove WebSocket server fed one robot's cycles (``cycle``)."""

    def __init__(
        self, *, robot: str | None, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT
    ) -> None:
        """Start the server on ``host``:``port`` (0: any free port; ``port`` then says which)
        and advertise every channel of the view; ``UsageError`` when the SDK is missing or
        the port cannot be had."""
        fox = require_sdk()
        self._fox = fox
        self.robot = robot
        self._context = fox.Context()
        try:
            self._server = fox.start_server(
                name="trace-audit tail", host=host, port=port, context=self._context
            )
        except Exception as err:  # the SDK raises its own error kinds for a taken port
            raise UsageError(f"cannot serve the live view on {host}:{port}: {err}") from err
        self.host = host
        self._view: FoxgloveView | None = None
        self._channels: dict[str, Any] = {}
        for topic, schema, encoding in view_channels():
            self._channel(topic, schema, encoding)
        for topic in (*LAYER_TOPICS, TOPIC_SEAL):
            self._channel(topic, logged_schema(topic), "json")
        self.cycles = 0

    @property
    def port(self) -> int:
        """The port the server listens on (the one it was given, or the free one it found)."""
        return int(self._server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def _channel(self, topic: str, schema: tuple[str, str, bytes], encoding: str) -> Any:
        channel = self._channels.get(topic)
        if channel is None:
            name, schema_encoding, data = schema
            sdk_schema = self._fox.Schema(name=name, encoding=schema_encoding, data=data)
            channel = self._fox.Channel(
                topic, schema=sdk_schema, message_encoding=encoding, context=self._context
            )
            self._channels[topic] = channel
        return channel

    def cycle(self, robot: str, cycle: Cycle) -> None:
        """Send one sealed cycle of ``robot`` (another robot's cycles are not shown)."""
        if self.robot is None:
            self.robot = robot
        if robot != self.robot:
            return
        if self._view is None:
            self._view = FoxgloveView(robot)
        self.cycles += 1
        if not any(channel.has_sinks() for channel in self._channels.values()):
            self._view.skip(cycle)  # no client subscribed: nothing to build or send
            return
        for msg in cycle.sensors:
            self._channel(msg.topic, logged_schema(msg.topic), "json").log(
                msg.data, log_time=msg.log_time_ns
            )
        for topic, data in cycle.payloads.items():
            if topic in self._channels:
                self._channels[topic].log(data, log_time=cycle.t_ns)
        for message in self._view.messages(cycle):
            self._channels[message.topic].log(message.data, log_time=message.t_ns)

    def close(self) -> None:
        """Stop the server (clients are disconnected) and close the channels."""
        self._server.stop()
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()
