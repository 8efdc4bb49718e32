"""Cold segments as streams of blocks: a message stream cut into blocks of whole cycles, the
plain messages kept beside each block and put back, each block's index entry, and the
reader's assembler, which turns a cold chunk's block back into the cycles of its tier.

Decoding a block gives back every message of the input (topic, sequence, log time and the
data, byte for byte), which the input tier's assembler then turns into cycles: seals verify
because the bytes they digest are unchanged.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

import orjson

from trace_runtime.encoding.cycles import Cycle, RawMessage, assemble_hot
from trace_runtime.errors import ColdFormatError, LogReadError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tier_formats.cold.cache import BlockCache
from trace_runtime.tier_formats.cold.format import (
    BLOCK_TOPIC,
    INDEX_TOPIC,
    PLAIN_TOPICS,
    gc_paused,
    malformed_as_format_error,
)
from trace_runtime.tier_formats.cold.seek import PartialBlock
from trace_runtime.tier_formats.warm import assemble_warm

Assembler = Callable[[Sequence[RawMessage], str], list[Cycle]]


def iter_blocks(messages: Iterable[RawMessage], block_cycles: int) -> Iterator[list[RawMessage]]:
    """Split a message stream into blocks of ``block_cycles`` sealed cycles each."""
    block: list[RawMessage] = []
    seals = 0
    for msg in messages:
        block.append(msg)
        if msg.topic == TOPIC_SEAL:
            seals += 1
            if seals == block_cycles:
                yield block
                block, seals = [], 0
    if block:
        yield block


def split_plain(
    block: Sequence[RawMessage],
) -> tuple[list[RawMessage], list[RawMessage], list[int]]:
    """(messages for the block, messages stored beside it, their positions in ``block``)."""
    kept: list[RawMessage] = []
    plain: list[RawMessage] = []
    positions: list[int] = []
    for position, msg in enumerate(block):
        if msg.topic in PLAIN_TOPICS:
            plain.append(msg)
            positions.append(position)
        else:
            kept.append(msg)
    return kept, plain, positions


def index_entry(block: Sequence[RawMessage]) -> dict[str, Any]:
    """The JSON index entry stored next to a block: counts and the chain anchors."""
    seals = [m for m in block if m.topic == TOPIC_SEAL]
    first = orjson.loads(seals[0].data) if seals else None
    last = orjson.loads(seals[-1].data) if seals else None
    return {
        "messages": len(block),
        "cycles": len(seals),
        "first_cycle": first.get("cycle") if isinstance(first, dict) else None,
        "last_cycle": last.get("cycle") if isinstance(last, dict) else None,
        "first_seal": hashlib.sha256(seals[0].data).hexdigest() if seals else None,
        "last_seal": hashlib.sha256(seals[-1].data).hexdigest() if seals else None,
    }


_INNER: dict[str, Assembler] = {"hot": assemble_hot, "warm": assemble_warm}
"""The tiers a cold block may hold the messages of (cold re-encodes a hot or a warm segment)."""


def assemble_cold(
    messages: Sequence[RawMessage], segment: str, cache: BlockCache | None = None
) -> list[Cycle]:
    """The reader's assembler for cold chunks: decode each block, assemble its cycles."""
    cache = cache if cache is not None else BlockCache(0)
    cycles: list[Cycle] = []
    for msg in messages:
        if msg.topic != BLOCK_TOPIC:
            continue
        try:
            block = cache.decode(msg.data)
        except ColdFormatError as err:
            raise LogReadError(segment, f"cold block {msg.sequence}: {err}") from err
        assembler = _INNER.get(block.tier)
        if assembler is None:
            raise LogReadError(segment, f"cold block holds messages of unknown tier {block.tier!r}")
        cycles += assembler(block.messages, segment)
    return cycles


class ColdAssembler:
    """The reader's assembler for the cold tier: a cycle run ends with its block. It owns the
    cache of recently decoded blocks; make one per reader to bound the cache's lifetime.
    ``limits`` bound what one block may make it do."""

    closer_topic = BLOCK_TOPIC

    def __init__(self, cache_blocks: int = 4, limits: ReadLimits = DEFAULT_LIMITS) -> None:
        self.cache = BlockCache(cache_blocks, limits)

    def __call__(self, messages: Sequence[RawMessage], segment: str) -> list[Cycle]:
        return assemble_cold(messages, segment, self.cache)

    def cycle_at(self, messages: Sequence[RawMessage], segment: str, t_ns: int) -> Cycle | None:
        """The last cycle of ``messages`` at or before ``t_ns`` (what ``__call__`` would give,
        filtered): a seek builds that one cycle, not the whole block."""
        for msg in reversed(messages):
            if msg.topic != BLOCK_TOPIC:
                continue
            try:
                found = self._block_cycle_at(msg.data, segment, t_ns)
            except ColdFormatError as err:
                raise LogReadError(segment, f"cold block {msg.sequence}: {err}") from err
            if found is not None:
                return found
        return None

    def _block_cycle_at(self, data: bytes, segment: str, t_ns: int) -> Cycle | None:
        block = self.cache.open(data)
        assembler = _INNER.get(block.tier)
        if assembler is None:
            raise LogReadError(segment, f"cold block holds messages of unknown tier {block.tier!r}")
        if isinstance(block, PartialBlock) and block.ends_sealed:
            with malformed_as_format_error():
                span = block.sealed_cycle_at(t_ns)
                if span is None:
                    return None
                with gc_paused():
                    cycles = assembler(block.messages(*span), segment)
                if len(cycles) != 1:
                    raise ColdFormatError("a seal's message range is not one cycle")
                return cycles[0]
        if isinstance(block, PartialBlock):
            block = self.cache.decode(data)  # an unsealed cycle at the end: decode it whole
        matching = [c for c in assembler(block.messages, segment) if c.t_ns <= t_ns]
        return matching[-1] if matching else None


def iter_decoded(
    messages: Iterable[RawMessage], cache: BlockCache | None = None
) -> Iterator[RawMessage]:
    """The original message stream behind a cold segment's messages, in the original order.

    ``messages`` is what ``Segment.iter_messages()`` gives for the whole segment: the plain
    messages of each chunk come before its block and are put back where they were. A caller
    that feeds a segment's messages a block at a time passes one ``cache`` for all of them.
    """
    cache = BlockCache(0) if cache is None else cache
    beside: list[RawMessage] = []
    for msg in messages:
        if msg.topic == BLOCK_TOPIC:
            block = cache.decode(msg.data)
            if len(block.plain) != len(beside):
                raise ColdFormatError("a block's plain messages are missing from its chunk")
            yield from merge_plain(block.messages, beside, block.plain)
            beside = []
        elif msg.topic in PLAIN_TOPICS:
            beside.append(msg)
        elif msg.topic != INDEX_TOPIC:
            yield msg
    yield from beside


def merge_plain(
    inner: list[RawMessage], plain: list[RawMessage], positions: list[int]
) -> Iterator[RawMessage]:
    """A block's messages with the plain ones put back at ``positions``."""
    pending = iter(inner)
    at = 0
    for position, msg in zip(positions, plain, strict=True):
        while at < position:
            yield next(pending)
            at += 1
        yield msg
        at += 1
    yield from pending
