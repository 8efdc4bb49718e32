"""The hand-over from the control thread to the writer: every item in order however the
threads interleave, and a wake-up never lost."""

from __future__ import annotations

import random
import threading
import time

import pytest

from trace_runtime.logger.handover import Handover, PendingCycle, Wakeup


def _pending(number: int) -> PendingCycle:
    return PendingCycle(number, number, {}, [], 0, -1)


def test_the_writer_side_sees_every_item_in_order_however_the_threads_interleave() -> None:
    handover = Handover(bound=64)
    seen: list[int] = []

    def consume() -> None:
        while True:
            batch = handover.take(most=random.randint(1, 8))
            if not batch:
                return
            seen.extend(p.cycle for p in batch)
            handover.done(len(batch))
            if random.random() < 0.05:
                time.sleep(0.0001)

    consumer = threading.Thread(target=consume)
    consumer.start()
    for number in range(20_000):
        handover.put(_pending(number), block=True)
        if number % 997 == 0:
            time.sleep(0.001)  # let the consumer fall asleep now and then
    assert handover.wait_idle(10.0)
    handover.close()
    consumer.join(10.0)
    assert not consumer.is_alive()
    assert seen == list(range(20_000))


@pytest.mark.parametrize("end", ["close", "abandon"])
def test_closing_wakes_a_sleeping_writer(end: str) -> None:
    handover = Handover(bound=4)
    got: list[list[PendingCycle]] = []
    consumer = threading.Thread(target=lambda: got.append(handover.take(most=4)))
    consumer.start()
    time.sleep(0.05)  # asleep by now
    getattr(handover, end)()
    consumer.join(5.0)
    assert not consumer.is_alive() and got == [[]]


def test_a_wakeup_left_pending_only_makes_the_next_sleep_return_early() -> None:
    wakeup = Wakeup()
    wakeup.wake()
    wakeup.wake()  # a second pending wake-up is the same one
    wakeup.sleep(lambda: False)  # returns at once: one was pending
    done = threading.Event()

    def sleeper() -> None:
        wakeup.sleep(lambda: False)
        done.set()

    thread = threading.Thread(target=sleeper)
    thread.start()
    assert not done.wait(0.05)  # nothing pending any more: it sleeps
    wakeup.notify()
    assert done.wait(5.0)
    thread.join()
