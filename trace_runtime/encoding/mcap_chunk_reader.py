"""Reading one file's chunks as an investigation asks for them: the last few decoded are
remembered (a seek, then a walk back, asks for neighbours), and a damaged chunk (fails its
CRC, does not decompress, holds broken records) is stepped over, recorded once with its
reason, and never decoded again. A limit hit is not damage: it is raised, and the file is
refused. One chunk's decoding is ``mcap_chunks``.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from pathlib import Path

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_chunks import ChunkDecoder
from trace_runtime.encoding.mcap_records import DAMAGE, damage_reason
from trace_runtime.errors import LogLimitError, LogReadError
from trace_runtime.read_limits import ReadLimits

__all__ = ["ChunkReader"]

log = logging.getLogger("trace_runtime")

_RECENT_CHUNKS = 4


class ChunkReader:
    """The chunks of one mapped file, decoded on demand (see the module doc)."""

    def __init__(self, path: Path, limits: ReadLimits) -> None:
        self.path = path
        self.decoder = ChunkDecoder(path, limits)
        self.skipped: list[tuple[int, str]] = []
        """Damaged chunks stepped over: (file offset, why)."""
        self.damaged: set[int] = set()
        self._recent: OrderedDict[int, list[RawMessage]] = OrderedDict()

    def messages(self, data: bytes, offset: int, topics: dict[int, str]) -> list[RawMessage]:
        """The messages of the chunk at ``offset`` (none for a damaged one)."""
        cached = self._recent.get(offset)
        if cached is not None:
            self._recent.move_to_end(offset)
            return cached
        messages = self._decode_or_skip(data, offset, topics, None)
        if offset in self.damaged:
            return messages
        self._recent[offset] = messages
        if len(self._recent) > _RECENT_CHUNKS:
            self._recent.popitem(last=False)
        return messages

    def on_topic(
        self, data: bytes, offsets: Sequence[int], topics: dict[int, str], topic: str
    ) -> Iterator[RawMessage]:
        """The messages on ``topic`` of the chunks at ``offsets``, without building the
        others; every chunk is still decoded and checked."""
        for offset in offsets:
            cached = self._recent.get(offset)
            if cached is not None:
                self._recent.move_to_end(offset)
                yield from (m for m in cached if m.topic == topic)
            else:
                yield from self._decode_or_skip(data, offset, topics, topic)

    def damage(self, data: bytes, offset: int, topics: dict[int, str]) -> str | None:
        """Why the chunk at ``offset`` does not decode (None if it does); a limit hit is
        raised."""
        try:
            self.decoder.decode(data, offset, topics)
        except LogLimitError:
            raise
        except LogReadError as err:
            return err.reason
        except DAMAGE as err:
            return f"chunk at offset {offset} is damaged ({type(err).__name__}: {err})"
        return None

    def skip(self, offset: int, reason: str) -> None:
        """Record the chunk at ``offset`` as damaged, and warn once."""
        if f"offset {offset}" not in reason:
            reason = f"chunk at offset {offset}: {reason}"
        self.damaged.add(offset)
        self.skipped.append((offset, reason))
        log.warning("%s: %s; its messages are skipped", self.path, reason)

    def clear(self) -> None:
        """Forget the recently decoded chunks."""
        self._recent.clear()

    def _decode_or_skip(
        self, data: bytes, offset: int, topics: dict[int, str], only: str | None
    ) -> list[RawMessage]:
        if offset in self.damaged:
            return []
        try:
            return self.decoder.decode(data, offset, topics, only)
        except LogLimitError:
            raise
        except LogReadError as err:
            self.skip(offset, err.reason)
        except DAMAGE as err:
            # What ``damage_as_read_error`` would say, without entering a context manager
            # for every chunk read (a chunk a cycle).
            self.skip(offset, damage_reason(err))
        return []
