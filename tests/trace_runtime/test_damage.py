"""A damaged file is read as far as it can be, or refused with LogReadError; never a crash."""

from __future__ import annotations

import contextlib
import logging
import struct
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trace_runtime import LogReadError, TimeOutOfRangeError, open_log


@pytest.fixture(scope="module")
def clean_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    from tests.trace_runtime.conftest import write_log

    path = tmp_path_factory.mktemp("clean") / "log.mcap"
    write_log(path, 12)
    return path.read_bytes()


def _read_everything(path: Path) -> int:
    log = open_log(path)
    count = 0
    for cycle in log.iter_cycles():
        cycle.digests()
        count += 1
    if count:
        # The summary's start may lie in a chunk that no longer reads: then no cycle is in
        # force there, which is a clear answer, not a crash.
        with contextlib.suppress(TimeOutOfRangeError):
            log.cycle_at(log.start_ns)
    return count


@settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_random_damage_is_read_or_refused(
    tmp_path: Path, clean_bytes: bytes, data: st.DataObject
) -> None:
    damaged = bytearray(clean_bytes)
    for _ in range(data.draw(st.integers(1, 8), label="flips")):
        at = data.draw(st.integers(0, len(damaged) - 1), label="offset")
        damaged[at] = data.draw(st.integers(0, 255), label="byte")
    path = tmp_path / f"damaged-{hash(bytes(damaged)) & 0xFFFFFFFF}.mcap"
    path.write_bytes(bytes(damaged))
    # Reading may succeed (the flip hit a payload or padding) or be refused with a clear
    # reason; any other exception escaping here is the failure this test exists to catch.
    with contextlib.suppress(LogReadError):
        _read_everything(path)


def test_a_damaged_summary_falls_back_to_reading_the_data(
    tmp_path: Path, clean_bytes: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    data = bytearray(clean_bytes)
    # Find the Statistics record through the Summary Offset records, then break its length
    # field: the summary is damaged, the data section is intact.
    footer = len(data) - 8 - 29
    offsets_start = struct.unpack_from("<Q", data, footer + 17)[0]
    statistics_at = next(
        struct.unpack_from("<Q", data, pos + 10)[0]
        for pos in range(offsets_start, footer, 26)
        if data[pos] == 0x0E and data[pos + 9] == 0x0B
    )
    assert data[statistics_at] == 0x0B
    struct.pack_into("<Q", data, statistics_at + 1, 2**40)  # runs far past the end of file
    path = tmp_path / "summary.mcap"
    path.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING, logger="trace_runtime"):
        log = open_log(path)
        assert [c.cycle for c in log.iter_cycles()] == list(range(12))
    assert any("damaged MCAP summary" in r.message for r in caplog.records)
