"""A TRACE log as Foxglove shows it: scene, decisions and plots, in Foxglove's own schemas.

``export_foxglove`` writes one robot's cycles (a window of them, or all) into one MCAP file
with the SDK's own message types, schemas and encoding (``foxglove-sdk``):

- ``/foxglove/scene`` (``foxglove.SceneUpdate``), one per cycle: the robot (where the cycle
  logs ``robot_pose``) and each perceived entity that has a position, as a cube with a text
  label (class, confidence, whether its evidence verified), coloured green when every
  evidence ref resolves, amber when the rest lie in a recording that could not be read
  (unknown), red otherwise (evidence FAILED). Each update first deletes the previous cycle's
  entities, so an entity lives exactly as long as the log perceives it. Positions are the
  log's x, y, z in the pose's own frame; nothing planar is assumed.
- ``/foxglove/robot_pose`` (``foxglove.PoseInFrame``) where the robot logs its pose.
- ``/foxglove/decisions`` (``foxglove.Log``): each decision change, its command, leading
  factor and rationale (``name`` the robot, ``file`` the segment, ``line`` the cycle).
- ``/foxglove/factors`` and ``/foxglove/actuators``: plain JSON numbers for the Plot panel
  (each factor by name; each actuator channel's intended, actual and deviation).
- the ``/trace/*`` and ``/sensors/*`` channels, copied through: each message's bytes are the
  canonical bytes its seal covers, with the segment's ``trace.session`` record (its
  ``prev_seal`` and ``first_cycle`` those of the first cycle exported), so the export is
  itself a TRACE log that ``trace-audit verify`` checks: clean from the log's start, and
  clean with a ``chain_start`` note from a later cycle (a window cut inside a segment carries
  a ``trace.excerpt`` record naming where it was cut, PROFILE section 2.1).

What each cycle shows is ``foxglove.view``'s (the live view shows the same); this module
writes it to one file beside the TRACE channels as logged.

``foxglove-sdk`` comes with the ``look`` extra; without it the export raises ``UsageError``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import orjson

from trace_audit.evidence import recordings_for
from trace_audit.foxglove.view import FoxgloveView, logged_schema, require_sdk
from trace_audit.log_source import LogSource, require_cycles
from trace_audit.log_time import TimeArg
from trace_audit.selection import Selection
from trace_runtime.encoding.cycles import Cycle
from trace_runtime.errors import StorageError, UsageError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.reading.recordings import Recordings
from trace_runtime.records import PROFILE, TOPIC_SEAL
from trace_runtime.session import EXCERPT_METADATA, SESSION_METADATA

__all__ = ["FoxgloveExport", "export_foxglove"]


@dataclass(frozen=True, slots=True)
class FoxgloveExport:
    """What an export wrote: the file, the robot, and how many of each kind of message."""

    path: str
    robot: str
    cycles: int
    scene_updates: int
    entities: int
    decision_changes: int
    trace_messages: int
    sensor_messages: int
    start_ns: int
    end_ns: int


def export_foxglove(
    source: LogSource,
    out: str | Path,
    *,
    robots: tuple[str, ...] = (),
    start: TimeArg = None,
    end: TimeArg = None,
    evidence: Sequence[str | Path] = (),
) -> FoxgloveExport:
    """Write one robot's cycles between ``start`` and ``end`` to ``out`` for Foxglove.

    One robot: ``robots`` selects it in a log of several (``SeveralRobotsError`` else). The
    file must not exist (``StorageError``), and the SDK must be installed (``UsageError``).
    Entities' evidence resolves as explain resolves it: the recordings the log declares,
    ``evidence`` (``--evidence``) for a moved copy."""
    from trace_audit.transitions import one_robot

    log = one_robot(source, robots, "decisions in this log")
    require_cycles(log)
    window = Selection(robots, start, end).window(log)
    target = Path(out)
    if target.exists():
        raise StorageError(str(target), "exists; the export never overwrites a file")
    require_sdk()
    cycles = log.iter_cycles(*window)  # one cycle at a time: an hour's export stays small
    first = next(cycles, None)
    if first is None:
        raise UsageError("no cycle of the log falls in the window")
    writer = _Writer(target, log, first, recordings_for(log, evidence))
    try:
        writer.cycle(first)
        for cycle in cycles:
            writer.cycle(cycle)
    except BaseException:
        writer.close()
        target.unlink(missing_ok=True)  # ours, half written: never left as if it were whole
        raise
    writer.close()
    return writer.result(str(target), log.first_robot)


class _Writer:
    """One export file: the view's messages, and the TRACE channels as logged.

    The file is written with the reference ``mcap`` writer, not the SDK's ``open_mcap``: a
    TRACE message's MCAP ``sequence`` is its cycle (PROFILE section 4), and the SDK's writer
    numbers every channel's messages itself, which would break the copied log."""

    def __init__(self, target: Path, log: Log, first: Cycle, recordings: Recordings | None) -> None:
        from mcap.writer import Writer

        session, source = _session(log, first)
        self.view = FoxgloveView(source.session.robot_id, source.session.period_ns, recordings)
        try:
            self.file = target.open("xb")
        except OSError as err:
            raise StorageError(str(target), err.strerror or str(err)) from err
        self.mcap: Any = Writer(self.file)  # the mcap package ships no type hints
        self.mcap.start(profile=PROFILE, library="trace-audit foxglove export")
        self.mcap.add_metadata(SESSION_METADATA, session)
        if source.session.first_cycle != first.cycle:
            # cut inside a segment: the chain starts at the seal before the window, and the
            # file says so (PROFILE section 2.1, trace.excerpt), so verify notes the start
            excerpt = {"source": source.path.name, "first_cycle": str(first.cycle)}
            self.mcap.add_metadata(EXCERPT_METADATA, excerpt)
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.trace_messages = self.sensor_messages = 0
        self.span = (first.t_ns, first.t_ns)

    def _channel(self, topic: str, schema: tuple[str, str, bytes], encoding: str) -> int:
        """The channel id of ``topic``, registered with ``schema`` (name, encoding, data)."""
        channel = self.channels.get(topic)
        if channel is None:
            name, schema_encoding, data = schema
            schema_id = self.schemas.get(name)
            if schema_id is None:
                schema_id = self.mcap.register_schema(name, schema_encoding, data)
                self.schemas[name] = schema_id
            channel = self.mcap.register_channel(topic, encoding, schema_id)
            self.channels[topic] = channel
        return channel

    def cycle(self, cycle: Cycle) -> None:
        """Everything one cycle contributes: its TRACE messages, then its view."""
        self.span = (self.span[0], cycle.t_ns)
        self._copy(cycle)
        for message in self.view.messages(cycle):
            channel = self._channel(message.topic, message.schema, message.encoding)
            self.mcap.add_message(channel, message.t_ns, message.data, message.t_ns)

    def _copy(self, cycle: Cycle) -> None:
        """The cycle's sensor readings and layer messages, their bytes as logged."""
        for msg in cycle.sensors:
            channel = self._channel(msg.topic, logged_schema(msg.topic), "json")
            self.mcap.add_message(channel, msg.log_time_ns, msg.data, msg.log_time_ns, msg.sequence)
            self.sensor_messages += 1
        seal = cycle.payloads.get(TOPIC_SEAL)
        layers = [(t, d) for t, d in cycle.payloads.items() if t != TOPIC_SEAL]
        # the seal closes its cycle, after every layer it covers
        for topic, data in [*layers, *([(TOPIC_SEAL, seal)] if seal is not None else [])]:
            channel = self._channel(topic, logged_schema(topic), "json")
            self.mcap.add_message(channel, cycle.t_ns, data, cycle.t_ns, cycle.cycle)
            self.trace_messages += 1

    def close(self) -> None:
        try:
            self.mcap.finish()
        finally:
            self.file.close()

    def result(self, path: str, robot: str) -> FoxgloveExport:
        view = self.view
        return FoxgloveExport(
            path,
            robot,
            view.cycles,
            view.scene_updates,
            view.entities,
            view.changes,
            self.trace_messages,
            self.sensor_messages,
            *self.span,
        )


def _session(log: Log, first: Cycle) -> tuple[dict[str, str], Segment]:
    """The ``trace.session`` of the export: that of the first exported cycle's segment, as a
    hot segment starting at that cycle (its chain continues from the seal before it), and
    that segment."""
    segment = log.segment_named(first.segment) or log.segments[0]
    seal = orjson.loads(first.payloads[TOPIC_SEAL]) if TOPIC_SEAL in first.payloads else {}
    prev = seal.get("prev") if isinstance(seal, dict) else None
    session = replace(
        segment.session,
        tier="hot",
        first_cycle=first.cycle,
        prev_seal=prev if isinstance(prev, str) else segment.session.prev_seal,
    )
    return session.to_metadata(), segment
