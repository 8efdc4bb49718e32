"""One TRACE segment read as decision cycles, whatever its chunking and compression.

``Segment`` stands on the byte layer (``mcap_file.McapFile``): it checks the profile and the
``trace.session`` record, then groups messages into cycles with the assembler of the
segment's tier. A cycle may span chunks (a re-chunking tool or another writer may cut
anywhere): the messages after the last closing message of a chunk (a seal, or a cold block)
lead into the next chunk, so every reader sees the same cycles however the file was cut.
"""

from __future__ import annotations

import bisect
import itertools
import logging
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from pydantic import ValidationError

from trace_runtime.chain import digest
from trace_runtime.encoding.cycles import Assembler, Cycle, HotAssembler, RawMessage
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.errors import LogReadError, NotTraceLogError
from trace_runtime.live_writers import is_live
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import PROFILE, TOPIC_SEAL, Seal
from trace_runtime.session import SESSION_METADATA, SessionInfo
from trace_runtime.tier_formats.cold import ColdAssembler
from trace_runtime.tier_formats.warm import WarmAssembler

log = logging.getLogger("trace_runtime")

ASSEMBLERS: Mapping[str, Callable[[ReadLimits], Assembler]] = {
    "hot": lambda _limits: HotAssembler(),
    "warm": lambda _limits: WarmAssembler(),
    "cold": lambda limits: ColdAssembler(limits=limits),
}
"""How each tier's messages become cycles (``trace.session`` ``tier``): one assembler per
segment, so a cache an assembler keeps (cold: decoded blocks) lives as long as the reader,
bounded by the reader's limits where decoding can be asked to inflate (cold blocks)."""

RECOVERED_WARNING = "%s: no footer (unfinished segment); recovered %d complete messages by scan"
"""What opening a segment its logger did not close, and no longer writes, logs (once a file:
callers that open one file twice filter on this message)."""

ChunkRead = Callable[[int | None, Sequence[RawMessage]], None]
"""What ``Segment.iter_cycles(chunk_read=...)`` is given: a chunk's file offset (None for the
messages outside chunks) and its messages."""

_MAX_LEAD_IN_CHUNKS = 4096
"""How far back a cycle's first messages are looked for (chunks of one message each hold a
cycle of a few dozen messages; a run of thousands of chunks without a seal is damage)."""


@dataclass(slots=True)
class SegmentInfo:
    """What a segment is, from its header, metadata and summary (or a scan)."""

    path: Path
    session: SessionInfo
    finished: bool
    recovered: bool
    """No footer and no writer: the logger died (a crash, a full disk); read by scan."""
    start_ns: int
    end_ns: int
    message_count: int
    chunk_count: int
    channels: dict[str, int]
    bytes: int
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    live: bool = False
    """No footer yet because its logger is still writing it (PROFILE §8)."""

    @property
    def tier(self) -> str:
        return self.session.tier


class Segment(McapFile):
    """A TRACE MCAP segment opened for reading."""

    def __init__(self, path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        super().__init__(path, limits)
        if self.profile != PROFILE:
            label = repr(self.profile) if self.profile else "none"
            raise NotTraceLogError(str(path), f"MCAP profile is {label}, not a TRACE log")
        if not self.has_metadata(SESSION_METADATA):
            raise NotTraceLogError(str(path), "no trace.session metadata record")
        self.session  # noqa: B018 - a malformed or merged session is refused at open
        self.start_ns: int
        self.end_ns: int
        trusted = self.trusted_statistics()
        if trusted is not None:
            self.start_ns, self.end_ns = trusted[0], trusted[1]
        elif self.finished:
            # No Statistics to go by (a stock writer's choice): the chunks' own time ranges
            # and the loose messages give the range without decoding a chunk.
            self.start_ns, self.end_ns = self.time_range()
        else:
            self.start_ns, self.end_ns = self.info.start_ns, self.info.end_ns
            if self.live:
                log.info("%s: being written; read up to its last complete chunk", self.path)
            else:
                log.warning(
                    RECOVERED_WARNING,
                    self.path,
                    self.info.message_count,
                )

    @cached_property
    def info(self) -> SegmentInfo:
        """What the segment is: session, time range, counts per channel, size, state."""
        start, end, chunk_count, channels = self.channel_counts()
        return SegmentInfo(
            path=self.path,
            session=self.session,
            finished=self.finished,
            recovered=not self.finished and not self.live,
            start_ns=start,
            end_ns=end,
            message_count=sum(channels.values()),
            chunk_count=chunk_count,
            channels=channels,
            bytes=self.size,
            metadata=dict(self.metadata),
            live=self.live,
        )

    @cached_property
    def live(self) -> bool:
        """Whether this segment has no footer because its logger is writing it right now."""
        return not self.finished and is_live(self.path, self.session.robot_id)

    @cached_property
    def session(self) -> SessionInfo:
        records = self.metadata_records(SESSION_METADATA)
        if not records:
            raise LogReadError(str(self.path), "the trace.session metadata record is damaged")
        if any(r != records[0] for r in records[1:]):
            robots = sorted({r.get("robot_id", "?") for r in records})
            who = f"robots {', '.join(robots)}" if len(robots) > 1 else f"robot {robots[0]}"
            raise LogReadError(
                str(self.path),
                f"holds {len(records)} different trace.session records ({who}): several "
                "segments merged into one file; a TRACE segment holds one session, so "
                "investigate the original files",
            )
        try:
            return SessionInfo.from_metadata(records[0])
        except ValueError as err:
            raise LogReadError(str(self.path), f"bad trace.session metadata: {err}") from err

    @cached_property
    def _assembler(self) -> Assembler:
        return ASSEMBLERS.get(self.session.tier, ASSEMBLERS["hot"])(self.limits)

    def clear_caches(self) -> None:
        """Forget recently decoded chunks and blocks (to measure a first read)."""
        super().clear_caches()
        cache = getattr(self._assembler, "cache", None)
        if cache is not None:
            cache.clear()

    # --- cycles across chunk boundaries ------------------------------------------------------

    def _closed_in(self, offset: int) -> tuple[list[RawMessage], list[RawMessage]]:
        """A chunk's messages split at its last closing message: (up to it, after it)."""
        messages = self.chunk_messages(offset)
        if not messages:
            return [], []
        closer = self._assembler.closer_topic
        for i in range(len(messages) - 1, -1, -1):
            if messages[i].topic == closer:
                return messages[: i + 1], messages[i + 1 :]
        return [], messages

    def _lead_in(self, offset: int) -> list[RawMessage]:
        """The messages before the chunk at ``offset`` that belong to its first cycle."""
        parts: list[list[RawMessage]] = []
        previous = self.previous_offset(offset)
        for _ in range(_MAX_LEAD_IN_CHUNKS):
            if previous is None:
                break
            closed, tail = self._closed_in(previous)
            if self.is_damaged(previous):
                break  # what came before the damage cannot be joined to what follows it
            parts.append(tail)
            if closed:
                break
            previous = self.previous_offset(previous)
        return [msg for part in reversed(parts) for msg in part]

    def _assemble(self, run: Sequence[RawMessage]) -> list[Cycle]:
        return self._assembler(run, self.path.name) if run else []

    def _chunk_run(
        self, offset: int, lead: list[RawMessage] | None = None
    ) -> tuple[list[RawMessage], list[RawMessage]]:
        """The messages of the cycles the chunk at ``offset`` closes (with their first
        messages from earlier chunks), and the messages it leaves open for the next chunk.
        The file's last chunk also gives the unfinished cycle after its last seal."""
        closed, tail = self._closed_in(offset)
        if self.is_damaged(offset):
            return [], []  # the cycle it cut is lost with it; verify reports the damage
        if lead is None:
            lead = self._lead_in(offset)
        if self.is_last_chunk(offset):
            closed, tail = closed + tail, []
        if not closed:
            return [], lead + tail
        return (lead + closed if lead else closed), tail

    def _chunk_cycles(
        self, offset: int, lead: list[RawMessage] | None = None
    ) -> tuple[list[Cycle], list[RawMessage]]:
        """The cycles the chunk at ``offset`` closes, and what it leaves open (``_chunk_run``)."""
        run, tail = self._chunk_run(offset, lead)
        return self._assemble(run), tail

    def _chunk_cycle_at(self, offset: int, t_ns: int) -> Cycle | None:
        """The last cycle the chunk at ``offset`` closes at or before ``t_ns``. An assembler
        that can build one cycle of a run (cold: without decoding the whole block) does."""
        run, _tail = self._chunk_run(offset)
        if not run:
            return None
        one_cycle = getattr(self._assembler, "cycle_at", None)
        if one_cycle is not None:
            found: Cycle | None = one_cycle(run, self.path.name, t_ns)
            return found
        cycles = [c for c in self._assemble(run) if c.t_ns <= t_ns]
        return cycles[-1] if cycles else None

    def _iter_runs(
        self, offsets: Sequence[int], chunk_read: ChunkRead | None = None
    ) -> Iterator[list[Cycle]]:
        """Cycles chunk by chunk, oldest first; what a chunk leaves open carries into the
        next without a second decode when the chunks follow each other in the file."""
        if self.loose:
            if chunk_read is not None:
                chunk_read(None, self.loose)
            yield self._assemble(self.loose)
        carried: list[RawMessage] = []
        previous: int | None = None
        order = self._file_order()  # what previous_offset bisects, fetched once, not per chunk
        for offset in offsets:
            at = bisect.bisect_left(order, offset)
            follows = previous is not None and at > 0 and order[at - 1] == previous
            if chunk_read is not None:
                chunk_read(offset, self.chunk_messages(offset))  # decoded once: remembered
            cycles, carried = self._chunk_cycles(offset, carried if follows else None)
            yield cycles
            previous = offset

    def iter_cycles(
        self,
        start_ns: int | None = None,
        end_ns: int | None = None,
        *,
        reverse: bool = False,
        chunk_read: ChunkRead | None = None,
    ) -> Iterator[Cycle]:
        """Cycles with ``start_ns <= t_ns <= end_ns``, in chain order (or newest first).

        ``chunk_read`` (oldest first only) is given each chunk the read takes up, its file
        offset and all its messages (a damaged one: none), before the chunk's cycles are
        yielded, and first ``None`` and the messages outside chunks: a check that needs
        messages no cycle holds (verify: the checkpoints) takes them from the same read."""
        if reverse and chunk_read is not None:
            raise ValueError("chunk_read is given chunks oldest first only")
        offsets = self.offsets_in_range(start_ns, end_ns)
        runs: Iterator[list[Cycle]]
        if reverse:
            runs = (self._chunk_cycles(o)[0] for o in reversed(offsets))
            if self.loose:
                runs = itertools.chain(runs, [self._assemble(self.loose)])
        else:
            runs = self._iter_runs(offsets, chunk_read)
        for cycles in runs:
            for cycle in reversed(cycles) if reverse else cycles:
                if (start_ns is None or cycle.t_ns >= start_ns) and (
                    end_ns is None or cycle.t_ns <= end_ns
                ):
                    yield cycle

    def cycle_at(self, t_ns: int) -> Cycle | None:
        """The cycle in force at ``t_ns``: the last one at or before it (None if none)."""
        # The chunk that starts last at or before t holds the answer unless t falls before
        # its first cycle: a chunk starts at its earliest sensor reading, which may precede
        # its cycle by several periods, and a closing checkpoint chunk holds no cycle. Step
        # back until a chunk has a cycle at or before t (a few chunks at most in practice).
        for offset in self.offsets_back_from(t_ns):
            found = self._chunk_cycle_at(offset, t_ns)
            if found is not None:
                return found
        if self.loose:
            cycles = [c for c in self._assemble(self.loose) if c.t_ns <= t_ns]
            if cycles:
                return cycles[-1]
        return None


def open_segment(path: str | Path, limits: ReadLimits = DEFAULT_LIMITS) -> Segment:
    """Open one segment file; raises ``LogReadError`` / ``NotTraceLogError``."""
    return Segment(path, limits)


def last_seal(source: Path | Segment) -> tuple[Seal, str] | None:
    """The last readable seal in a segment (a file, or one already open) and its digest (to
    continue a chain after a restart). Damage never stops a robot from logging: a damaged
    seal is passed over, and a segment that cannot be read gives None (the caller then tries
    an older one; `verify` reports the resulting break)."""
    try:
        segment = source if isinstance(source, Segment) else Segment(source)
        for cycle in segment.iter_cycles(reverse=True):
            data = cycle.payloads.get(TOPIC_SEAL)
            if data is None:
                continue
            try:
                return Seal.model_validate_json(data), digest(data)
            except ValidationError:
                continue
    except LogReadError:
        return None
    return None
