"""Whether one copy of a segment stands for another: a replacement that is exactly what its
source becomes, and what ``verify`` finds in one segment on its own."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from itertools import zip_longest
from pathlib import Path

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import VerificationError
from trace_runtime.reading.logset import Log
from trace_runtime.reading.reader import Segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.session import TIER_METADATA
from trace_runtime.tier_formats.cold import iter_decoded
from trace_runtime.tier_formats.warm import WarmPolicy, warm_cycles
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.verification import verify

__all__ = ["chain_problems", "verify_replacement"]


def verify_replacement(source: Segment, replacement: Path) -> None:
    """Raise ``VerificationError`` unless ``replacement`` is exactly what ``source`` becomes."""
    target = Segment(replacement)
    tier = target.session.tier
    if replace(target.session, tier=source.session.tier) != source.session:
        raise VerificationError(f"{replacement.name}: session record differs from the source's")
    if tier == "cold":
        _same(source.iter_messages(), iter_decoded(target.iter_messages()), replacement)
        if (target.info.start_ns, target.info.end_ns) != (source.info.start_ns, source.info.end_ns):
            raise VerificationError(f"{replacement.name}: time range differs from the source's")
    elif tier == "warm":
        policy = WarmPolicy.from_metadata(target.metadata.get(TIER_METADATA, {}))
        expected = (
            m
            for c in warm_cycles(source.iter_messages(), policy, source.session.period_ns)
            for m in c.messages
        )
        _same(expected, target.iter_messages(), replacement)
        # Independently of how summaries are made: every seal must be there, byte for byte.
        _same(
            (m for m in source.iter_messages() if m.topic == TOPIC_SEAL),
            (m for m in target.iter_messages() if m.topic == TOPIC_SEAL),
            replacement,
        )
    else:
        raise VerificationError(f"{replacement.name}: tier {tier!r} is not a compaction target")


def _same(expected: Iterator[RawMessage], actual: Iterator[RawMessage], path: Path) -> None:
    for count, (want, got) in enumerate(zip_longest(expected, actual)):
        if want != got:
            if want is None or got is None:
                raise VerificationError(f"{path.name}: message count differs from the source's")
            raise VerificationError(
                f"{path.name}: message {count} ({want.topic} at {want.log_time_ns}) differs"
            )


def chain_problems(segment: Segment, limit: int = 10, key: PublicKey | None = None) -> list[str]:
    """What ``verify`` finds in one segment on its own (its chain entering where its
    ``trace.session`` says), one line each; empty when it verifies."""
    report = verify(Log([segment], segment.path.parent), key=key)
    return [f"{f.kind}: {f.message}" for f in report.findings[:limit]]
