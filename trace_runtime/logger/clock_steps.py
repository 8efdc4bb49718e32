"""Clock steps on the writer: a cycle begun earlier than the one before it.

A robot's clock can step back under it: chrony stepping the system clock, a simulator or bag
replay reset under ``use_sim_time``. Time must not go back within a segment (PROFILE section
4), and the control loop must not get an exception for it, so the writer ends the segment at
the step and writes the cycles from it on into the next one, whose ``trace.session`` declares
the step (``clock_step_from_ns``, the time before it). The chain and the cycle numbers go on
across it as across any rotation; readers see two runs of the clock (``Log.clock_steps``).
"""

from __future__ import annotations

from trace_runtime.logger.chain_writer import ChainWriter
from trace_runtime.logger.handover import PendingCycle

__all__ = ["write_across_steps"]


def write_across_steps(chain: ChainWriter, batch: list[PendingCycle]) -> None:
    """Write ``batch`` through ``chain``, cut where time goes back: each cycle earlier than
    the one before it (in this batch or, for the first, the last written) begins a segment
    that declares the step. Swallows every failure, as ``ChainWriter.write_batch`` does."""
    start = 0
    for index, pending in enumerate(batch):
        before = batch[index - 1].t_ns if index else chain.last_t_ns
        if before is not None and pending.t_ns < before:
            if index > start:
                chain.write_batch(batch[start:index])
            chain.step_clock(before, pending)
            start = index
    chain.write_batch(batch[start:] if start else batch)
