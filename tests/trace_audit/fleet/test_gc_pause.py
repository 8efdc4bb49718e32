"""The index pauses the cyclic garbage collector while it builds a segment's rows, and gives
it back as it found it, also when tasks overlap in threads (a Dask worker's)."""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator

import pytest

from trace_audit.fleet.task import _CyclicGcPause


@pytest.fixture
def collector_on() -> Iterator[None]:
    was = gc.isenabled()
    gc.enable()
    yield
    if not was:
        gc.disable()


def test_the_collector_is_paused_inside_and_back_after_an_error(collector_on: None) -> None:
    pause = _CyclicGcPause()
    with pytest.raises(ValueError), pause.paused():
        assert not gc.isenabled()
        raise ValueError("a task that fails")
    assert gc.isenabled()


def test_a_collector_the_caller_turned_off_stays_off() -> None:
    was = gc.isenabled()
    gc.disable()
    try:
        with _CyclicGcPause().paused():
            pass
        assert not gc.isenabled()
    finally:
        if was:
            gc.enable()


def test_overlapping_tasks_give_it_back_when_the_last_leaves(collector_on: None) -> None:
    pause = _CyclicGcPause()
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen: list[bool] = []

    def first() -> None:
        with pause.paused():
            first_in.set()
            second_in.wait(5)
        first_out.set()

    def second() -> None:
        first_in.wait(5)
        with pause.paused():
            second_in.set()
            first_out.wait(5)
            seen.append(gc.isenabled())  # the first task left: still paused for this one

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert seen == [False]
    assert gc.isenabled()
