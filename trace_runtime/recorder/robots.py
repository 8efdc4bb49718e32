"""The robots a recorder writes: one ``AuditLogger`` per connected robot id under one log
root, and a cycle message written through it as an in-process robot would write it.

A robot id is claimed by one connection at a time; the claim ends after its logger closed
(and let go of the robot's writer lock), so a client that reconnects at once is refused
until then, never handed a logger another connection is still using. A reconnecting robot
gets a new logger, which continues the robot's chain in a new segment, as a restarted
in-process robot does.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from trace_runtime.errors import TraceError, UsageError
from trace_runtime.logger.api import AuditLogger
from trace_runtime.logger.config import LoggerConfig
from trace_runtime.recorder.protocol import CycleMessage, Hello
from trace_runtime.records import EvidenceRef

__all__ = ["RobotLog", "Robots"]


@dataclass(slots=True)
class RobotLog:
    """One connected robot: its logger and what the recorder counted for it."""

    hello: Hello
    logger: AuditLogger
    received: int = 0
    """Cycle messages taken from the client (written or refused)."""
    refused: int = 0
    """Frames of this robot refused with an error (bad message, bad record, time going back)."""
    declared_dropped: int = 0
    """Cycles the client said it dropped, declared in the chain by the next seal."""
    _undeclared: int = 0  # drops a client declared that no cycle has carried into the chain yet

    def write(self, message: CycleMessage) -> None:
        """Log one cycle message through the logger's own builder: its records are checked
        by the same record models, and a refused cycle is aborted, so the next seal counts
        it. Raises the ``RecordError`` or ``UsageError`` the logger raised."""
        self.received += 1
        log = self.logger
        self._undeclared += message.dropped
        # A dropped cycle leaves its number unused and the next seal declares it (PROFILE
        # section 7): the logger does exactly that for an aborted cycle. A time that went back
        # is the logger's declared clock step (section 4); a negative one raises RecordError.
        while self._undeclared:
            log.cycle(message.t_ns).abort()
            self._undeclared -= 1
            self.declared_dropped += 1
        builder = log.cycle(message.t_ns)
        try:
            refs = [builder.sensor(s.topic, s.data, s.log_time_ns) for s in message.sensors]
            perception = message.layers.get("perception")
            if perception is not None and refs:
                _complete_refs(perception, refs)
            for name, record in message.layers.items():
                getattr(builder, name)(record)
        except TraceError:
            builder.abort()
            raise
        builder.commit()

    def counters(self) -> dict[str, Any]:
        """What a ``stats`` request answers for this robot."""
        stats = self.logger.stats
        return {
            "robot_id": self.hello.robot_id,
            "received": self.received,
            "refused": self.refused,
            "declared_dropped": self.declared_dropped,
            "committed": stats.committed,
            "written": stats.written,
            "dropped": stats.dropped,
            "segments": len(stats.segments),
        }


def _complete_refs(perception: dict[str, Any], refs: list[EvidenceRef]) -> None:
    """Give each evidence ref that names a reading of this cycle (same topic and log time,
    no sequence, no recording) the sequence and digest the logger gave that reading: a
    client cannot know them (the recorder numbers a robot's readings per topic). Anything
    of another shape is left for the record models to judge."""
    found: dict[tuple[str, int], EvidenceRef] = {}
    for reading in refs:
        found.setdefault((reading.topic, reading.log_time_ns), reading)
    entities = perception.get("entities")
    for entity in entities if isinstance(entities, list) else ():
        evidence = entity.get("evidence") if isinstance(entity, dict) else None
        for item in evidence if isinstance(evidence, list) else ():
            ref = item.get("ref") if isinstance(item, dict) else None
            if not isinstance(ref, dict) or ref.get("sequence") is not None:
                continue
            topic, log_time = ref.get("topic"), ref.get("log_time_ns")
            if ref.get("recording") is not None or not isinstance(topic, str):
                continue
            if not isinstance(log_time, int) or isinstance(log_time, bool):
                continue
            cited = found.get((topic, log_time))
            if cited is not None and ref.get("digest") in (None, cited.digest):
                item["ref"] = cited.model_dump()


class Robots:
    """One ``AuditLogger`` per connected robot id, under one log root."""

    def __init__(self, root: Path, config: LoggerConfig) -> None:
        self.root = root
        self.config = config
        self._lock = threading.Lock()
        self._claimed: dict[str, RobotLog | None] = {}  # None: its logger is being opened

    def claim(self, hello: Hello) -> RobotLog:
        """Open the logger of ``hello``'s robot for one connection. ``UsageError`` when
        another connection holds the robot id; the logger's own errors (``LogLockedError``:
        another process writes this robot's log here) pass through."""
        robot_id = hello.robot_id
        with self._lock:
            if robot_id in self._claimed:
                raise UsageError(f"robot id {robot_id!r} is already connected to this recorder")
            self._claimed[robot_id] = None
        try:
            logger = AuditLogger(
                self.root,
                robot_id=robot_id,
                period_s=hello.period_ns / 1e9,
                software_version=hello.software_version,
                policy_version=hello.policy_version,
                clock=hello.clock,
                config=replace(self.config, recordings=hello.recordings)
                if hello.recordings
                else self.config,
            )
        except BaseException:
            with self._lock:
                del self._claimed[robot_id]
            raise
        robot = RobotLog(hello, logger)
        with self._lock:
            self._claimed[robot_id] = robot
        return robot

    def release(self, robot: RobotLog, timeout_s: float | None = 5.0) -> None:
        """Close the robot's logger (its queue written, its segment finished), then free
        the robot id for the next connection."""
        try:
            robot.logger.close(timeout_s)
        finally:
            with self._lock:
                self._claimed.pop(robot.hello.robot_id, None)

    def connected(self) -> list[str]:
        with self._lock:
            return sorted(self._claimed)
