"""The writer side of an ``AuditLogger``: seals committed cycles into the robot's hash chain
and writes them, a chunk per batch, into segments it rotates, checkpoints and replaces.

Failure policy (schemas/PROFILE.md, "Dropped cycles"): nothing here raises. A failed write,
a lost disk or permission drops the batch and counts it; the first failure of each kind is
logged once through ``logging``; the next seal written carries the count in ``dropped``, and
drops after the last seal are declared in ``trace.close`` when the segment ends. A failed
write that could not be rolled back is judged by the file's real end, as a reader will judge
it: a batch whose chunk is in the file whole counts as written and the next segment chains
from its last seal; one cut short is dropped and declared. A segment file whose header could
not be written holds nothing and is removed. A segment deleted under the writer is noticed
at the next batch and replaced. The segment opener and the checkpoint signer are plug points
that may raise anything, so the boundary around them catches ``Exception``: a bug there
costs cycles (counted and logged), never the robot.

Every method but ``rotate_key`` runs on one thread at a time: the writer thread, or the
control thread with ``threaded=False`` (``logger.writer_thread`` holds the lock).
"""

from __future__ import annotations

import contextlib
import logging
import os
import time
from pathlib import Path
from typing import BinaryIO

from trace_runtime.chain import NO_SENSORS, digest, sensor_cover, sensor_line
from trace_runtime.costs import TIMING_METADATA, CostHistogram
from trace_runtime.encoding.codec import (
    EncodedLayer,
    digest_keeping_gil,
    encode_layer,
    encode_seal_fields,
)
from trace_runtime.errors import NoteError, SegmentWriteError, UsageError
from trace_runtime.logger.checkpointer import Checkpointer
from trace_runtime.logger.config import LoggerConfig, LoggerStats, default_opener, default_origin
from trace_runtime.logger.cycle_builder import COST_SAMPLE_EVERY
from trace_runtime.logger.handover import PendingCycle
from trace_runtime.logger.lock import WriterLock
from trace_runtime.logger.mcap_out import MessageFields, OutMessage
from trace_runtime.logger.recording_seals import (
    RecordingBatch,
    RecordingSeals,
    encode_recording_seal,
)
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.logger.witness_feed import witness_feed_for
from trace_runtime.recording_records import TOPIC_RECORDING
from trace_runtime.records import GENESIS, LAYER_MODELS, TOPIC_SEAL
from trace_runtime.segment_names import rotated_segment_name, segment_name
from trace_runtime.session import SessionInfo
from trace_runtime.tlog.keys import Signer
from trace_runtime.tlog.merkle import EMPTY_ROOT, CompactRange, leaf_hash
from trace_runtime.tlog.signed_note import format_checkpoint

__all__ = ["CLOSE_METADATA", "ChainWriter"]

log = logging.getLogger("trace_runtime")

CLOSE_METADATA = "trace.close"
"""Metadata a segment ends with when cycles were dropped after its last seal."""

_NO_READINGS = (0, NO_SENSORS)
"""The ``sensors`` of a cycle without readings: written too, so that readings added to such
a cycle are found as surely as readings taken away from another."""


class ChainWriter:
    """One robot's chain on disk: the open segment, the last seal, what is still undeclared.

    ``path`` is the log's file or root (``is_root``); ``stats`` is the logger's, updated
    here. ``writer_lock`` is renewed when the storage under it was deleted. The first
    segment is opened at once, continuing the chain from ``session.prev_seal``: when that
    fails (bad path, no permission) it raises, a set-up error the integrator must see,
    unlike every later I/O failure.
    """

    def __init__(
        self,
        path: Path,
        session: SessionInfo,
        *,
        is_root: bool,
        config: LoggerConfig,
        stats: LoggerStats,
        signer: Signer | None,
        writer_lock: WriterLock | None,
    ) -> None:
        self.path = path
        self.is_root = is_root
        self.config = config
        self.stats = stats
        self._writer_lock = writer_lock
        self._opener = config.opener or default_opener
        self.undeclared = 0
        """Cycles the writer dropped since the last seal written (failed writes, lost storage)."""
        self._reported: set[str] = set()
        self._last_sync = time.monotonic()
        self._segment: SegmentWriter | None = None
        self._segment_start_ns: int | None = None
        self._head: tuple[int, int] | None = None  # (cycle, t_ns) of the segment's last seal
        self.last_t_ns: int | None = None
        """The time of the last cycle written, in any segment (``logger.clock_steps``)."""
        self._step_from: int | None = None  # a clock step the next segment opened declares
        self._sealed_in_segment = 0
        self._costs = CostHistogram()  # this segment's per-cycle control-thread costs
        self.session = session
        self.prev_seal = session.prev_seal
        self.origin = config.origin or default_origin(session.robot_id)
        """The C2SP origin of the robot's checkpoints and the key name of their notes."""
        try:
            format_checkpoint(self.origin, 0, EMPTY_ROOT)
        except NoteError as err:
            raise UsageError(f"LoggerConfig.origin {self.origin!r} cannot be one: {err}") from err
        self._checkpoints = Checkpointer(
            config, stats, origin=self.origin, signer=signer, report_once=self.report_once
        )
        self.tree: CompactRange | None = self._first_tree(path, session)
        """The robot's Merkle tree through ``prev_seal`` (profile 1.2); None when it could not
        be resumed (checkpoints then carry no tree, counted in ``stats.tree_failures``)."""
        self._feed = witness_feed_for(
            config,
            self.tree if self._checkpoints.note_signer is not None else None,
            store_root=path if is_root else path.parent,
            robot_id=session.robot_id,
            stats=stats,
            report_once=self.report_once,
        )
        self._batch_leaves: list[bytes] = []  # this batch's leaves, for the witness feed
        self._recordings = RecordingSeals.declared(
            session, path if is_root else path.parent, config, self.report_once
        )
        self.open_segment(session)

    def _first_tree(self, path: Path, session: SessionInfo) -> CompactRange | None:
        """The tree the first segment continues: empty at genesis, else resumed from the
        root (``resume.resume_tree``) once, at start."""
        if session.prev_seal == GENESIS:
            return CompactRange()
        if not self.is_root:
            return None
        from trace_runtime.logger.resume import resume_tree  # reads the root; only when resuming

        tree = resume_tree(path, session.robot_id, session.prev_seal)
        if tree is None:
            self.report_once(
                "tree",
                "the robot's Merkle tree could not be resumed from the log (its chain could "
                "not be followed to the last seal): checkpoints are written without it",
            )
        return tree

    def rotate_key(self, signer: Signer) -> None:  # the control thread's: under a lock
        self._checkpoints.rotate(signer)

    @property
    def segment(self) -> SegmentWriter | None:
        """The segment being written (None between a lost one and the next batch)."""
        return self._segment

    def crash(self) -> None:
        """Stop as a killed process would: every written batch stays on disk, the open
        segment gets no summary nor closing checkpoint, and the writer lock is gone (the
        kernel drops it with the process). For tests of crash recovery."""
        segment, self._segment = self._segment, None
        if segment is not None:
            segment._stream.flush()
            os.fsync(segment._stream.fileno())
            segment._stream.close()
        self.release_lock()

    def release_lock(self) -> None:
        """Let go of the robot's writer lock (the log is finished)."""
        if self._writer_lock is not None:
            self._writer_lock.release()

    def step_clock(self, before_ns: int, pending: PendingCycle) -> None:
        """End the segment before ``pending``, whose time is earlier than ``before_ns`` (the
        clock stepped back: ``logger.clock_steps``); the next segment opened declares it."""
        self.stats.clock_steps += 1
        self.report_once(
            "clock_step",
            f"the clock went back {(before_ns - pending.t_ns) / 1e9:.3f} s at cycle "
            f"{pending.cycle}: a new segment declares the step (PROFILE section 4)",
        )
        self._step_from = before_ns
        self.close_segment()

    def write_batch(self, batch: list[PendingCycle]) -> None:
        """Seal and write cycles, one caller at a time (``WriterThread`` holds its lock).
        Swallows every failure."""
        tree = self.tree
        saved = tree.state() if tree is not None else None  # a dropped batch takes its leaves
        self._batch_leaves = []
        self._checkpoints.take_note()  # one a dropped batch made is not offered
        try:
            self.check_storage()
            self._maybe_rotate(batch[0].t_ns)
            if self._segment is None:
                step, first = self._step_from, batch[0].cycle
                self.open_segment(self.session.next_segment(self.prev_seal, first, step))
                self._step_from = None  # declared
            segment = self._segment
            if segment is None:
                raise SegmentWriteError("no segment could be opened", rolled_back=False)
            recorded = self._recordings.collect() if self._recordings is not None else None
            messages, last_seal, checkpoints = self._seal(segment, batch, recorded)
            self.stats.bytes_written += segment.write_batch(messages)
        except SegmentWriteError as err:
            if not err.kept:
                self._lose(batch, err, abandon=not err.rolled_back)
                self._restore_tree(saved)
                return
            # The batch is in the file, the segment can take no more: the batch counts as
            # written, and the next segment continues the chain from its last seal.
            self.stats.bytes_written += err.written
            self.report_once(f"io:{type(err).__name__}", f"audit write failed: {err}")
            self._segment = None
        except Exception as err:
            self._lose(batch, err, abandon=True)
            self._restore_tree(saved)
            return
        self.prev_seal = last_seal
        self.undeclared = 0
        if recorded is not None and self._recordings is not None:
            self._recordings.written()
        self.stats.written += len(batch)
        self._head = (batch[-1].cycle, batch[-1].t_ns)
        self.last_t_ns = batch[-1].t_ns
        self._sealed_in_segment += len(batch)
        self.stats.checkpoints += checkpoints
        feed = self._feed
        if feed is not None:
            feed.add_leaves(self._batch_leaves)
            note = self._checkpoints.take_note()
            if note is not None:
                feed.offer(*note)
            feed.submit()
        if self._segment_start_ns is None:
            self._segment_start_ns = batch[0].t_ns
        for pending in batch:
            if pending.cost_ns >= 0:  # -1: not a timed cycle
                self._costs.add(pending.cost_ns)
        self._maybe_sync()

    def _restore_tree(self, saved: tuple[int, list[bytes]] | None) -> None:
        """A batch that is not on disk leaves no leaves in the tree."""
        if saved is not None:
            self.tree = CompactRange.restore(*saved)

    def _seal(
        self, segment: SegmentWriter, batch: list[PendingCycle], recorded: RecordingBatch | None
    ) -> tuple[list[MessageFields], str, int]:
        """The batch's messages in file order, the last seal's digest, and how many periodic
        checkpoints are among the messages (each right after the seal it names).

        Messages are plain tuples and the channel ids are looked up once per batch: this
        loop runs five or more times per cycle on the writer, holding the GIL."""
        messages: list[MessageFields] = []
        append = messages.append
        checkpoints = 0
        prev = self.prev_seal
        carried = self.undeclared
        channel = segment.channel
        layer_channels = {topic: channel(topic) for topic in LAYER_MODELS}
        seal_channel = channel(TOPIC_SEAL)
        tree = self.tree
        grow = tree.append if tree is not None else None
        keep = self._batch_leaves.append if self._feed is not None else None
        for index, pending in enumerate(batch):
            cycle, t_ns = pending.cycle, pending.t_ns
            lines: list[bytes] = []
            for topic, sequence, log_time, data, data_digest in pending.sensors:
                append((channel(topic), sequence, log_time, data))
                lines.append(sensor_line(topic, sequence, log_time, data_digest))
            digests: dict[str, str] = {}
            for topic, record in pending.layers.items():
                if isinstance(record, EncodedLayer):  # a dict, encoded on the control thread
                    data, digests[topic] = record
                else:
                    data = encode_layer(cycle, t_ns, record, LAYER_MODELS[topic])
                    digests[topic] = digest_keeping_gil(data)
                append((layer_channels[topic], cycle, t_ns, data))
            if recorded is not None and index == 0:
                data = encode_recording_seal(cycle, t_ns, recorded)
                digests[TOPIC_RECORDING] = digest_keeping_gil(data)
                append((channel(TOPIC_RECORDING), cycle, t_ns, data))
            cover = sensor_cover(lines) if lines else _NO_READINGS
            data = encode_seal_fields(
                cycle, t_ns, digests, prev, carried + pending.dropped_before, sensors=cover
            )
            append((seal_channel, cycle, t_ns, data))
            prev = digest(data)
            if grow is not None:
                leaf = leaf_hash(data)  # the seal's leaf: one hash, and one node amortised
                grow(leaf)
                if keep is not None:
                    keep(leaf)
            carried = 0
            if self._checkpoints.due(t_ns, self._segment_start_ns):
                sealed = self._sealed_in_segment + index + 1
                checkpoint = self._checkpoint(segment, cycle, t_ns, prev, sealed, final=False)
                if checkpoint is not None:
                    append(checkpoint)
                    checkpoints += 1
        return messages, prev, checkpoints

    def _lose(self, batch: list[PendingCycle], err: Exception, *, abandon: bool) -> None:
        self.stats.dropped_io += len(batch)
        self.undeclared += len(batch) + sum(p.dropped_before for p in batch)
        self.report_once(f"io:{type(err).__name__}", f"audit write failed, dropping cycles: {err}")
        if abandon and self._segment is not None:
            # The file cannot be trusted past its last good batch; readers recover up to it.
            with contextlib.suppress(Exception):  # already failing; nothing more to do
                self._segment._stream.close()
            self._segment = None

    def check_storage(self) -> None:
        """A segment deleted under the writer (its directory removed) is lost with every
        cycle sealed into it: give it up so the next batch opens a new segment (recreating
        the directory) that continues the chain from the last seal, and whose first seal
        declares the lost cycles as dropped (schemas/PROFILE.md §7). One fstat per batch."""
        segment = self._segment
        if segment is None or not segment.storage_lost():
            return
        lost = self._sealed_in_segment
        self.stats.written -= lost
        self.stats.dropped_storage_lost += lost
        self.undeclared += lost
        path = self.stats.segments[-1] if self.stats.segments else self.path
        self.report_once(
            "storage",
            f"audit storage lost: {path} was deleted under the writer with {lost} cycle(s); "
            "going on in a new segment",
        )
        with contextlib.suppress(OSError, ValueError):  # nothing to save in an unlinked file
            segment._stream.close()
        self._segment = None
        if self._writer_lock is not None:
            self._writer_lock.renew(self.report_once)

    def _maybe_rotate(self, t_ns: int) -> None:
        segment = self._segment
        if segment is None or not self.is_root or self._segment_start_ns is None:
            return
        too_long = t_ns - self._segment_start_ns >= self.config.max_segment_s * 1e9
        if too_long or segment.offset >= self.config.max_segment_bytes:
            self.close_segment()

    def open_segment(self, session: SessionInfo) -> None:
        path = self._segment_path(session)
        path.parent.mkdir(parents=True, exist_ok=True)
        stream = self._opener(path)
        opened = _identity(stream)  # before a failed header closes the stream
        try:
            segment = SegmentWriter(stream, session, level=self.config.compression_level)
        except BaseException:
            _give_up_header(stream, path, opened)
            raise
        self._segment = segment
        self.session = session
        self._segment_start_ns = None
        self._head = None
        self._sealed_in_segment = 0
        self._checkpoints.new_segment()
        self._costs = CostHistogram()
        self.stats.segments.append(path)

    def declare_tail(self, undeclared_control: int) -> None:
        """Drops after the last seal have no next seal to declare them: say so at close in a
        ``trace.close`` metadata record (schemas/PROFILE.md §7), so the gap is not silent."""
        tail = undeclared_control + self.undeclared
        segment = self._segment
        if tail == 0 or segment is None or segment.broken:
            return
        last = self._head[0] if self._head is not None else self.session.first_cycle - 1
        try:
            segment.add_metadata(
                CLOSE_METADATA,
                {"dropped_after_last_seal": str(tail), "last_sealed_cycle": str(last)},
            )
        except Exception as err:
            self.report_once("close", f"could not record the dropped tail: {err}")

    def close_segment(self) -> None:
        segment, self._segment = self._segment, None
        if segment is None:
            return
        head = self._head
        if head is not None and not segment.broken and not self._final_checkpoint(segment, *head):
            # A finished segment without its closing checkpoint reads as cut short
            # (docs/integrity.md): leave it unfinished, as a crash would, for readers to scan.
            with contextlib.suppress(Exception):  # the opener's stream: a plug point
                segment._stream.close()
            return
        if self._costs.cycles and not segment.broken:
            # The logger's own cost per cycle, for Table II of `trace-audit metrics`.
            try:
                segment.add_metadata(TIMING_METADATA, self._costs.to_metadata(COST_SAMPLE_EVERY))
            except Exception as err:
                self.report_once("timing", f"could not record the logger's cost: {err}")
        try:
            segment.close()
        except Exception as err:
            self.report_once("close", f"could not finish segment: {err}")

    def _checkpoint(
        self, segment: SegmentWriter, cycle: int, t_ns: int, head: str, sealed: int, *, final: bool
    ) -> OutMessage | None:
        """A checkpoint of the chain head ``head`` (the seal of ``cycle``); None if it could
        not be built."""
        return self._checkpoints.message(
            segment,
            self.session,
            self.tree,
            cycle=cycle,
            t_ns=t_ns,
            head=head,
            sealed=sealed,
            final=final,
        )

    def _final_checkpoint(self, segment: SegmentWriter, cycle: int, t_ns: int) -> bool:
        """Write the segment's closing checkpoint (its last seal: ``cycle`` at ``t_ns``);
        whether it is in the file."""
        self._checkpoints.take_note()
        message = self._checkpoint(
            segment, cycle, t_ns, self.prev_seal, self._sealed_in_segment, final=True
        )
        note = self._checkpoints.take_note()  # the batch's own come after
        if message is None:
            return False
        try:
            self.stats.bytes_written += segment.write_batch([message])
        except SegmentWriteError as err:
            self.report_once("checkpoint", f"could not write a checkpoint: {err}")
            if not err.kept:
                self.stats.checkpoint_failures += 1
                return False
            self.stats.bytes_written += err.written  # in the file; the segment is given up
        except Exception as err:
            self.stats.checkpoint_failures += 1
            self.report_once("checkpoint", f"could not write a checkpoint: {err}")
            return False
        self.stats.checkpoints += 1
        if self._feed is not None and note is not None:
            self._feed.offer(*note)
            self._feed.submit()
        return True

    def _segment_path(self, session: SessionInfo) -> Path:
        if not self.is_root:
            if session.segment == 0 or not self.stats.segments:
                return self.path
            return self.path.with_name(rotated_segment_name(self.path.stem, session.segment))
        return self.path / "hot" / segment_name(session.robot_id, session.segment)

    def _maybe_sync(self) -> None:
        interval = self.config.fsync_interval_s
        if interval is None or self._segment is None:
            return
        now = time.monotonic()
        if now - self._last_sync >= interval:
            self._last_sync = now
            try:
                self._segment.sync()
            except OSError as err:
                self.report_once("fsync", f"fsync failed: {err}")

    def report_once(self, kind: str, message: str) -> None:
        if kind not in self._reported:
            self._reported.add(kind)
            log.warning("%s (reported once; see AuditLogger.stats)", message)


def _identity(stream: BinaryIO) -> tuple[int, int] | None:
    """(device, inode) of the file behind an opened stream; None without a descriptor."""
    try:
        stat = os.fstat(stream.fileno())
    except (AttributeError, OSError, ValueError):  # no descriptor (a stream in memory)
        return None
    return stat.st_dev, stat.st_ino


def _give_up_header(stream: BinaryIO, path: Path, opened: tuple[int, int] | None) -> None:
    """A new segment's header could not be written: close its stream and remove the file,
    which holds no cycle (a reader would call it damaged). Only when ``path`` is still the
    file the stream was opened on (``opened``: device and inode), an opener may write
    elsewhere than ``path``."""
    with contextlib.suppress(Exception):  # the header failed; the file is given up
        stream.close()
    if opened is None:
        return
    with contextlib.suppress(OSError):  # gone already, or not ours to remove: leave it
        there = os.lstat(path)
        if (there.st_dev, there.st_ino) == opened:
            os.unlink(path)
