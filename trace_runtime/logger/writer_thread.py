"""Where and when an ``AuditLogger``'s cycles are written: on a background writer thread fed
by the hand-over queue (robots), or at ``commit`` on the control thread (``threaded=False``),
and how the log ends within a bounded time even when the disk hangs.

The writer thread takes batches from the ``Handover`` and writes each through the
``ChainWriter`` under one lock; it lets go of the GIL only for the batch's compression and
write (``trace_runtime.logger.handover`` says why). ``close`` waits at most its timeout: what is
still queued or being written then is counted as undelivered, and should the disk come back
the thread (a daemon) still ends the segment, declares those cycles in ``trace.close`` and
keeps the robot's writer lock until then.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from trace_runtime.logger.chain_writer import ChainWriter
from trace_runtime.logger.clock_steps import write_across_steps
from trace_runtime.logger.config import LoggerConfig
from trace_runtime.logger.handover import Handover, PendingCycle

__all__ = ["WriterThread"]


class WriterThread:
    """The writing of one logger's cycles, threaded or synchronous, and its bounded end.

    ``undeclared_control`` reads the control thread's count of cycles it dropped since the
    last hand-over; the log's last segment declares them when it ends.
    """

    def __init__(
        self,
        chain: ChainWriter,
        config: LoggerConfig,
        undeclared_control: Callable[[], int],
    ) -> None:
        self._chain = chain
        self._config = config
        self._undeclared_control = undeclared_control
        self._lock = threading.Lock()  # one writer of the chain at a time
        # close() giving up on a hung writer, and the writer finishing a batch after that,
        # settle ``stats.dropped_undelivered`` under this lock (see close()).
        self._accounting = threading.Lock()
        self._gave_up = False
        self._closing_cycles = 0  # threaded=False: cycles close() handed to the closer
        self._sync_batch: list[PendingCycle] = []  # threaded=False, batch_cycles > 1
        self.queue: Handover | None = None
        """The hand-over the control thread puts cycles into; None with ``threaded=False``."""
        self._thread: threading.Thread | None = None
        if config.threaded:
            self.queue = Handover(config.queue_cycles)
            self._thread = threading.Thread(
                target=self._run, name=f"trace-writer-{chain.session.robot_id}", daemon=True
            )
            self._thread.start()

    def write_now(self, pending: PendingCycle) -> None:
        """``threaded=False``: add a committed cycle, writing once ``batch_cycles`` are in."""
        self._sync_batch.append(pending)
        if len(self._sync_batch) >= self._config.batch_cycles:
            batch, self._sync_batch = self._sync_batch, []
            with self._lock:
                write_across_steps(self._chain, batch)

    def flush(self, timeout_s: float) -> bool:
        """Wait until every committed cycle has been written; True if it got there."""
        if self.queue is None:
            return True
        return self.queue.wait_idle(timeout_s)

    def close(self, timeout_s: float | None) -> bool:
        """Write what is queued, then end the log; wait at most ``timeout_s`` (None: as long
        as it takes) and count what is left as undelivered. True when the writer finished."""
        if self.queue is not None and self._thread is not None:
            self.queue.close()
            finisher = self._thread
        else:
            batch, self._sync_batch = self._sync_batch, []
            self._closing_cycles = len(batch)
            finisher = threading.Thread(
                target=self._finish,
                args=(batch,),
                name=f"trace-close-{self._chain.session.robot_id}",
                daemon=True,
            )
            finisher.start()
        finisher.join(timeout_s)
        if timeout_s is not None and finisher.is_alive():
            self._give_up(timeout_s)
            return False
        return True

    def _give_up(self, timeout_s: float) -> None:
        """close() timed out: count what the writer still holds as undelivered."""
        stats = self._chain.stats
        with self._accounting:
            self._gave_up = True
            if self.queue is not None:
                self.queue.abandon()
                undelivered = self.queue.undone
            else:
                undelivered = self._closing_cycles
            stats.dropped_undelivered += undelivered
        self._chain.report_once(
            "close-timeout",
            f"audit log close timed out after {timeout_s:g} s (storage hung?): "
            f"{undelivered} cycle(s) not written",
        )

    def _run(self) -> None:
        handover = self.queue
        assert handover is not None
        stats = self._chain.stats
        while True:
            batch = handover.take(self._config.max_batch_cycles)
            if not batch:
                break  # closed and drained, or abandoned by a close() that timed out
            with self._lock:
                write_across_steps(self._chain, batch)
            with self._accounting:
                handover.done(len(batch))
                if self._gave_up:  # close() counted this batch as undelivered; it is not
                    stats.dropped_undelivered -= len(batch)
        # What close() took out of the queue is declared in trace.close like any drop.
        skipped = handover.discarded
        self._finish([], skipped=len(skipped) + sum(p.dropped_before for p in skipped))

    def _finish(self, batch: list[PendingCycle], *, skipped: int = 0) -> None:
        """End the log: write ``batch``, declare the undeclared tail, close the segment, let
        go of the writer lock. On the writer thread, or a closer thread (threaded=False)."""
        chain = self._chain
        try:
            with self._lock:
                if batch:
                    write_across_steps(chain, batch)
                    with self._accounting:
                        if self._gave_up:
                            chain.stats.dropped_undelivered -= len(batch)
                        self._closing_cycles = 0
                chain.undeclared += skipped
                chain.check_storage()
                chain.declare_tail(self._undeclared_control())
                chain.close_segment()
        finally:
            chain.release_lock()
