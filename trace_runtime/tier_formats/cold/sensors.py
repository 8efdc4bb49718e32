"""A 1.3 seal's ``sensors`` digest, derived from the block's own messages.

A seal's ``sensors.digest`` (``trace_runtime.chain.sensor_cover``) is 64 hex characters that
look random to zstd, but it is a function of messages the block holds anyway: the readings
(messages on ``/sensors/`` topics, ``records.SENSOR_PREFIX``, as ``seal_check`` counts them)
logged since the previous seal. The encoder stores it as *derived* when it equals that
function of the block (one byte a seal, constant for an honest log) and as a literal
otherwise, so a tampered seal still round-trips exactly. Encoder, whole decode and seek
compute it here, from the same rule.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable, Sequence
from typing import Final

from trace_runtime.chain import sensor_cover, sensor_line
from trace_runtime.records import SENSOR_PREFIX, TOPIC_SEAL

_LINE_BYTES = 128
"""What each message a seal's cycle spans is charged when its cover is computed (a reading's
line, its topic, numbers and digest, is ~100 bytes)."""

SENSOR_DIGEST_PATH: Final = ("sensors", "digest")
"""The leaf path of a seal's sensors digest (the column the derived coding is tried on)."""


class _Derived:
    """The value a derived sensors digest decodes to, until the block resolves it."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "DERIVED"


DERIVED: Final = _Derived()
"""Stands in a row for a sensors digest recomputed from the block (``SensorCovers.cover``);
orjson refuses to serialise it, so one left unresolved can never become a message."""


class SensorCovers:
    """Which messages of a block are each cycle's readings: for a message at position i,
    those on a ``/sensors/`` topic after the last seal before i (or the block's start: a
    block starts on a cycle boundary), in block order."""

    __slots__ = ("_is_reading", "_names", "_seals", "_sequences", "_times", "_topic_ids")

    def __init__(
        self,
        topic_names: Sequence[str],
        topic_ids: Sequence[int],
        sequences: Sequence[int],
        times: Sequence[int],
    ) -> None:
        self._names = topic_names
        self._topic_ids = topic_ids
        self._sequences = sequences
        self._times = times
        self._is_reading = [name.startswith(SENSOR_PREFIX) for name in topic_names]
        seal_id = topic_names.index(TOPIC_SEAL) if TOPIC_SEAL in topic_names else -1
        self._seals = [i for i, topic_id in enumerate(topic_ids) if topic_id == seal_id]

    def cycle_start(self, at: int) -> int:
        """Where the cycle of the message at ``at`` starts: after the last seal before it."""
        before = bisect_left(self._seals, at)
        return self._seals[before - 1] + 1 if before else 0

    def readings(self, at: int) -> list[int]:
        """Positions of the readings the message at ``at`` covers, if it is a seal."""
        is_reading, topic_ids = self._is_reading, self._topic_ids
        return [i for i in range(self.cycle_start(at), at) if is_reading[topic_ids[i]]]

    def derived(
        self, values: Sequence[str], at_rows: Sequence[int], digests: Sequence[str]
    ) -> tuple[bytes, list[str]]:
        """The encoder's side: for each seal's sensors digest (``values``, at message
        positions ``at_rows``), a flag (1: the cover of its readings in the block, derived
        again on decoding) and the literals that are not. The encoder computes covers from its
        own input, so they are charged nothing."""
        flags = bytearray()
        literals: list[str] = []
        for value, at in zip(values, at_rows, strict=True):
            derived = self.cover(at, digests.__getitem__, _free) == value
            flags.append(derived)
            if not derived:
                literals.append(value)
        return bytes(flags), literals

    def cover(
        self, at: int, digest_of: Callable[[int], str | None], spend: Callable[[int], None]
    ) -> str | None:
        """The sensors digest of the seal at ``at``, its readings' data digests taken from
        ``digest_of`` (None when one of them is not built yet: then None). What it hashes is
        charged to ``spend`` first: a hostile block could ask this of every message of a
        long cycle, over all the readings before it."""
        spend(_LINE_BYTES * (at - self.cycle_start(at) + 1))
        readings = self.readings(at)
        names, topic_ids, sequences, times = (
            self._names,
            self._topic_ids,
            self._sequences,
            self._times,
        )
        lines = []
        for i in readings:
            data_digest = digest_of(i)
            if data_digest is None:
                return None
            lines.append(sensor_line(names[topic_ids[i]], sequences[i], times[i], data_digest))
        return sensor_cover(lines)[1]


def _free(_size: int) -> None:
    """Nothing is charged (see ``SensorCovers.derived``)."""
