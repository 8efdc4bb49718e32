"""Writing a segment's copy in a compacted tier, aside as its partial file, and checking
that the file on disk holds exactly what was written.

A cold copy is checked block by block as it is encoded (each block decodes to the source's
messages); a warm copy carries a tally of the source's seals. Either way the partial file is
read back at the end and every chunk compared with a digest of what was written.
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from itertools import islice
from pathlib import Path
from typing import Any, BinaryIO, cast

import orjson

from trace_runtime.costs import TIMING_METADATA
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.errors import ColdFormatError, LogReadError, SegmentWriteError, VerificationError
from trace_runtime.logger.mcap_out import OutMessage
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.reading.reader import Segment
from trace_runtime.records import MESSAGE_MODELS, TOPIC_SEAL
from trace_runtime.session import TIER_METADATA, SessionInfo
from trace_runtime.tier_formats.cold import (
    BLOCK_SCHEMA,
    BLOCK_TOPIC,
    CODEC,
    INDEX_SCHEMA,
    INDEX_TOPIC,
    BlockEncoder,
    gc_paused,
    index_entry,
    iter_blocks,
    merge_plain,
    split_plain,
)
from trace_runtime.tier_formats.warm import SUMMARY_SCHEMA, SUMMARY_TOPIC, WarmPolicy, warm_cycles
from trace_runtime.tiers._files import PARTIAL_METADATA, PartialOpener, PartialStream, partial_path
from trace_runtime.tiers.catalog import file_digest
from trace_runtime.tiers.report import ColdOptions, rel_path

WARM_CHUNK_CYCLES = 256
WARM_LEVEL = 9


def write_replacement(
    root: Path,
    path: Path,
    segment: Segment,
    tier: str,
    *,
    warm_policy: WarmPolicy,
    cold_options: ColdOptions,
    advance: Callable[[int], None],
    opener: PartialOpener,
) -> Written | str:
    """Write the ``tier`` copy of a segment aside as its partial file, fsync it and check that
    it holds exactly what was written; the failure detail (a str) if not, the partial gone."""
    target_dir = root / tier
    try:
        target_dir.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        # Something else sits at the tier's name (a FIFO, a file someone planted): it is not
        # ours to replace, and nothing is written through it.
        return f"{tier}/ in the root is not a folder; nothing was written there"
    target = target_dir / path.name
    partial = partial_path(target)
    if target.exists():
        return f"{rel_path(root, target)} exists already and is not this segment's copy"
    try:
        file = opener(partial)
    except FileExistsError:
        return f"a file not made by compaction is in the way: {rel_path(root, partial)}"
    except OSError as err:
        return f"cannot create {rel_path(root, partial)}: {err}"
    # From here on the partial is the file this run created: ours to remove on failure.
    try:
        source_sha = file_digest(path)
        with PartialStream(file) as stream:
            if tier == "cold":
                written = _write_cold(segment, stream, source_sha, cold_options, advance)
            else:
                written = _write_warm(segment, stream, source_sha, warm_policy, advance)
        _check_written(segment, partial, written)
    except (VerificationError, LogReadError, ColdFormatError, SegmentWriteError, OSError) as err:
        with contextlib.suppress(OSError):
            partial.unlink()
        return str(err)
    return written


def _tier_session(segment: Segment, tier: str) -> SessionInfo:
    return replace(segment.session, tier=tier)


def _tier_metadata(segment: Segment, tier: str, source_sha: str, **extra: str) -> dict[str, str]:
    lossy = (
        "true"
        if tier == "warm" or segment.metadata.get(TIER_METADATA, {}).get("lossy") == "true"
        else "false"
    )
    note = (
        "lossy: routine cycles are summaries (seal kept in full; layer messages pruned; "
        "sensor readings dropped unless keep_readings); flagged cycles and their context are "
        "byte-exact copies"
        if tier == "warm"
        else "lossless re-encoding of its source: decoding gives back every message byte for byte"
    )
    if tier == "cold" and lossy == "true":
        note += " (the source was a lossy warm segment)"
    # Whether the robot's logger closed the original (verify then requires its closing
    # checkpoint): a hot source says so itself, a compacted one passes it on.
    finished = (
        str(segment.info.finished).lower()
        if segment.session.tier == "hot"
        else segment.metadata.get(TIER_METADATA, {}).get("source_finished")
    )
    return {
        "tier": tier,
        "source_tier": segment.session.tier,
        "source_sha256": source_sha,
        "source_bytes": str(segment.info.bytes),
        "lossy": lossy,
        "note": note,
        **({} if finished is None else {"source_finished": finished}),
        **extra,
    }


class _Tally:
    """A running digest of a message stream: what was written, or what is read back."""

    def __init__(self) -> None:
        self._sha = hashlib.sha256()
        self.count = 0

    def add(self, topic: str, sequence: int, log_time_ns: int, data: bytes) -> None:
        self._sha.update(b"%d %d %d %d " % (len(topic), sequence, log_time_ns, len(data)))
        self._sha.update(topic.encode())
        self._sha.update(data)
        self.count += 1

    @property
    def digest(self) -> str:
        return self._sha.hexdigest()


def _batch_digest(rows: Iterable[tuple[str, int, int, bytes]]) -> str:
    """SHA-256 of a batch of messages: their (topic, sequence, log time, size) and data."""
    rows = list(rows)
    sha = hashlib.sha256(orjson.dumps([(t, s, at, len(d)) for t, s, at, d in rows]))
    sha.update(b"".join(row[3] for row in rows))
    return sha.hexdigest()


@dataclass(slots=True)
class Written:
    """What a tier writer wrote (a digest per chunk) and, for warm, the seals it carried."""

    batches: list[tuple[int, str]]
    seals: _Tally
    full_cycles: int | None = None


class _TallyWriter:
    """A SegmentWriter that records a digest of every batch (chunk) it writes."""

    def __init__(self, writer: SegmentWriter) -> None:
        self.writer = writer
        self.batches: list[tuple[int, str]] = []
        self._topics: dict[int, str] = {}

    def channel(self, topic: str, **kwargs: Any) -> int:
        channel = self.writer.channel(topic, **kwargs)
        self._topics[channel] = topic
        return channel

    def write_batch(self, batch: list[OutMessage]) -> None:
        self.writer.write_batch(batch)
        topics = self._topics
        rows = ((topics[m.channel_id], m.sequence, m.log_time_ns, m.data) for m in batch)
        self.batches.append((len(batch), _batch_digest(rows)))


def _as_tuples(messages: list[RawMessage]) -> list[tuple[str, int, int, bytes]]:
    return [(m.topic, m.sequence, m.log_time_ns, m.data) for m in messages]


def _open_writer(
    segment: Segment, stream: PartialStream, tier: str, **options: Any
) -> _TallyWriter:
    """A SegmentWriter on a partial file whose first write carries compaction's marker."""
    marker = {"partial": segment.path.name, "tier": tier}
    # The logger's cost statistics describe the source's cycles, which every tier keeps (in
    # full or summarised): `trace-audit metrics` reads them from whichever copy it opens.
    carried = [
        (name, segment.metadata[name]) for name in (TIMING_METADATA,) if name in segment.metadata
    ]
    writer = SegmentWriter(
        cast(BinaryIO, stream),  # PartialStream has every method SegmentWriter uses
        _tier_session(segment, tier),
        extra_metadata=[(PARTIAL_METADATA, marker), *carried],
        **options,
    )
    stream.release()
    return _TallyWriter(writer)


def _write_cold(
    segment: Segment,
    stream: PartialStream,
    source_sha: str,
    options: ColdOptions,
    advance: Callable[[int], None],
) -> Written:
    # Blocks are zstd-compressed already; a second compression of the chunk would only cost time.
    out = _open_writer(segment, stream, "cold", compression="")
    counts = {"blocks": 0, "cycles": 0, "messages": 0, "verbatim": 0}
    # Nothing a compaction makes is cyclic: the cyclic GC would only walk the blocks in
    # flight again and again (reference counting still frees everything).
    with gc_paused():
        _encode_blocks(segment, out, options, counts, advance)
    blocks, cycles = counts["blocks"], counts["cycles"]
    out.writer.add_metadata(
        TIER_METADATA,
        _tier_metadata(
            segment,
            "cold",
            source_sha,
            codec=CODEC,
            block_cycles=str(options.block_cycles),
            blocks=str(blocks),
            cycles=str(cycles),
            messages=str(counts["messages"]),
            verbatim_messages=str(counts["verbatim"]),
        ),
    )
    out.writer.finish()
    return Written(out.batches, _Tally())


def _encode_blocks(
    segment: Segment,
    out: _TallyWriter,
    options: ColdOptions,
    counts: dict[str, int],
    advance: Callable[[int], None],
) -> None:
    """Encode the segment's blocks, check each against the source, write each as a chunk."""
    block_channel = out.channel(BLOCK_TOPIC, encoding=CODEC, schema=BLOCK_SCHEMA)
    index_channel = out.channel(INDEX_TOPIC, encoding="json", schema=INDEX_SCHEMA)
    source_tier = segment.session.tier
    encoder = BlockEncoder(options.level)
    source = iter_blocks(segment.iter_messages(), options.block_cycles)
    for number, block in enumerate(source):
        kept, plain, positions = split_plain(block)
        raw_before = encoder.raw_messages
        data, _decoded = encoder.encode_checked(kept, source_tier, positions)
        # The block, decoded again with its plain messages put back, must be the source
        # block as it was read, message for message. encode_checked proved that the block
        # decodes to ``kept``, message for message, with its plain ones at ``positions``;
        # this catches a pipeline that gave it something else. Comparing ``kept`` itself
        # rather than its decoded copies proves the same and finds the source's own objects
        # in both lists, so == compares pointers (~6 us a cycle, 1.5% of a compaction).
        if list(merge_plain(kept, plain, positions)) != block:
            raise VerificationError(f"block {number} does not decode to the source messages")
        entry = index_entry(block)
        first = min(m.log_time_ns for m in block)
        last = max(m.log_time_ns for m in block)
        out.write_batch(
            [
                *(
                    OutMessage(out.channel(m.topic), m.sequence, m.log_time_ns, m.data)
                    for m in plain
                ),
                OutMessage(block_channel, number, first, data),
                OutMessage(index_channel, number, last, orjson.dumps(entry)),
            ]
        )
        counts["blocks"] += 1
        counts["cycles"] += entry["cycles"]
        counts["messages"] += len(block) - len(plain)
        counts["verbatim"] += encoder.raw_messages - raw_before
        advance(entry["cycles"])


def _write_warm(
    segment: Segment,
    stream: PartialStream,
    source_sha: str,
    policy: WarmPolicy,
    advance: Callable[[int], None],
) -> Written:
    out = _open_writer(segment, stream, "warm", level=WARM_LEVEL)
    out.channel(SUMMARY_TOPIC, schema=SUMMARY_SCHEMA)
    seals = _Tally()

    def source() -> Iterator[RawMessage]:
        # The seals of the source, tallied as they are read, to check the copy independently.
        for msg in segment.iter_messages():
            if msg.topic == TOPIC_SEAL:
                seals.add(msg.topic, msg.sequence, msg.log_time_ns, msg.data)
            yield msg

    batch: list[OutMessage] = []
    in_batch = full = summaries = 0
    for cycle in warm_cycles(source(), policy, segment.session.period_ns):
        for msg in cycle.messages:
            channel = _channel(out, msg.topic)
            batch.append(OutMessage(channel, msg.sequence, msg.log_time_ns, msg.data))
        sealed = cycle.messages[-1].topic == TOPIC_SEAL  # not the closing checkpoint alone
        full += cycle.full and sealed
        summaries += not cycle.full
        in_batch += 1
        if in_batch >= WARM_CHUNK_CYCLES:
            out.write_batch(batch)
            advance(in_batch)
            batch, in_batch = [], 0
    if batch:
        out.write_batch(batch)
        advance(in_batch)
    out.writer.add_metadata(
        TIER_METADATA,
        _tier_metadata(
            segment,
            "warm",
            source_sha,
            full_cycles=str(full),
            summary_cycles=str(summaries),
            **policy.to_metadata(),
        ),
    )
    out.writer.finish()
    return Written(out.batches, seals, full)


def _check_written(source: Segment, partial: Path, written: Written) -> None:
    """The file on disk holds exactly what was written (and verified), nothing else."""
    target = Segment(partial)
    if replace(target.session, tier=source.session.tier) != source.session:
        raise VerificationError(f"{partial.name}: session record differs from the source's")
    seals = _Tally()
    messages = target.iter_messages()
    for count, want in written.batches:
        batch = list(islice(messages, count))
        for msg in batch:
            if msg.topic == TOPIC_SEAL:
                seals.add(msg.topic, msg.sequence, msg.log_time_ns, msg.data)
        if len(batch) != count or _batch_digest(_as_tuples(batch)) != want:
            raise VerificationError(f"{partial.name}: the file does not hold what was written")
    if next(messages, None) is not None:
        raise VerificationError(f"{partial.name}: the file holds more than was written")
    if target.session.tier == "warm":
        if (seals.count, seals.digest) != (written.seals.count, written.seals.digest):
            raise VerificationError(f"{partial.name}: seals differ from the source's")
    elif (target.info.start_ns, target.info.end_ns) != (source.info.start_ns, source.info.end_ns):
        raise VerificationError(f"{partial.name}: time range differs from the source's")


def _channel(writer: _TallyWriter, topic: str) -> int:
    if topic.startswith("/trace/") and topic not in MESSAGE_MODELS and topic != SUMMARY_TOPIC:
        # A /trace topic this version has no schema for (a newer writer): keep it, schemaless.
        return writer.channel(topic, schema=("trace.Unknown", "", b""))
    return writer.channel(topic)
