"""A hot segment read while its logger writes it: each poll decodes only what was appended.

``reader.Segment`` opens a file as it is at that moment; a segment without a footer is then
found by a walk of its whole data section, every chunk decoded. ``GrowingSegment`` follows
it with ``growing_mcap.GrowingMcap`` (each poll reads only the records appended since the
last) and assembles the cycles those records close. What it keeps between polls is bounded:
the file offset, the channel table, the session, and the messages of a cycle whose seal is
not written yet.

It reads the hot tier only (a warm or cold segment is written whole, aside, and then
finished: ``reader.Segment`` reads those), with the hot tier's assembly (``cycles``), so a
cycle read here is the cycle ``Segment`` reads. A damaged chunk is stepped over as the reader
steps over one (the cycle it cut is lost with it); a limit hit is raised.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator
from pathlib import Path

from trace_runtime.encoding.cycles import Cycle, RawMessage, assemble_hot
from trace_runtime.encoding.mcap_records import read_str
from trace_runtime.errors import LogReadError, NotHotSegmentError, NotTraceLogError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.reading.growing_mcap import GrowingMcap
from trace_runtime.records import PROFILE, TOPIC_SEAL
from trace_runtime.session import SESSION_METADATA, SessionInfo

__all__ = ["GrowingSegment", "NotHotSegmentError"]

log = logging.getLogger("trace_runtime")


class GrowingSegment(GrowingMcap):
    """One hot segment followed as it grows (``poll``), from its first byte or, after a
    first poll, from where the last complete record read ends."""

    def __init__(self, path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        super().__init__(path, limits)
        self.session: SessionInfo | None = None
        """The segment's ``trace.session`` record, once read (the first poll that reaches it)."""
        self._open: list[RawMessage] = []
        self._open_bytes = 0

    def poll(self) -> Iterator[Cycle]:
        """The cycles the records appended since the last poll close (sealed ones; the
        messages after the last seal wait for theirs), oldest first, a chunk at a time.

        Raises ``LogReadError`` when the file is gone, shrank under what was read or is not
        a TRACE hot segment, and ``LogLimitError`` when a record breaks the reader's limits."""
        for messages in self.poll_records():
            yield from self._cycles(messages)

    def _check_profile(self, profile: str) -> None:
        if profile != PROFILE:
            label = repr(profile) if profile else "none"
            raise NotTraceLogError(str(self.path), f"MCAP profile is {label}, not a TRACE log")

    def _metadata(self, body: bytes) -> None:
        with self._as_read_error():
            name, pos = read_str(body, 0)
            if name != SESSION_METADATA:
                return
            (map_len,) = struct.unpack_from("<I", body, pos)
            pos += 4
            stop = pos + map_len
            values: dict[str, str] = {}
            while pos < stop:
                key, pos = read_str(body, pos)
                values[key], pos = read_str(body, pos)
        try:
            session = SessionInfo.from_metadata(values)
        except ValueError as err:
            raise LogReadError(str(self.path), f"bad trace.session metadata: {err}") from err
        if self.session is not None and session != self.session:
            raise LogReadError(str(self.path), "holds two different trace.session records")
        if session.tier != "hot":
            raise NotHotSegmentError(
                str(self.path), f"a {session.tier} segment is read whole, not followed"
            )
        self.session = session

    def _skip(self, offset: int, reason: str) -> None:
        super()._skip(offset, reason)
        self._open, self._open_bytes = [], 0  # the cycle the damaged chunk cut is lost

    # --- cycles --------------------------------------------------------------------------

    def _cycles(self, messages: list[RawMessage]) -> list[Cycle]:
        """The cycles closed by a seal among the open messages and ``messages``; what follows
        the last seal stays open for the next poll (bounded: a run past the chunk limit
        without a seal is damage, and is dropped)."""
        if not messages:
            return []
        last = -1
        for i in range(len(messages) - 1, -1, -1):
            if messages[i].topic == TOPIC_SEAL:
                last = i
                break
        run = self._open + messages[: last + 1] if last >= 0 else []
        rest = messages[last + 1 :] if last >= 0 else self._open + messages
        self._open = rest
        self._open_bytes = sum(len(m.data) for m in rest)
        if self._open_bytes > self.limits.max_chunk_bytes:
            log.warning("%s: %d bytes without a seal dropped", self.path, self._open_bytes)
            self._open, self._open_bytes = [], 0
        return assemble_hot(run, self.path.name) if run else []
