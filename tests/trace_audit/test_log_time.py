"""log_time: a time given at the CLI is read exactly, and a relative one against the log start."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.trace_audit.conftest import T0_NS
from trace_audit.log_time import LogClock, TimePoint, exact_seconds
from trace_runtime import open_log
from trace_runtime.clock import EARLIEST_WALL_NS
from trace_runtime.errors import UsageError


@pytest.mark.parametrize(
    ("text", "ns", "relative"),
    [
        ("12.3", 12_300_000_000, False),
        ("12.3s", 12_300_000_000, False),
        ("+0.5", 500_000_000, True),
        ("1700000000.123456789", 1_700_000_000_123_456_789, False),
        ("0", 0, False),
    ],
)
def test_time_point_parses_seconds_exactly(text: str, ns: int, relative: bool) -> None:
    assert TimePoint.parse(text) == TimePoint(ns, relative)


@pytest.mark.parametrize("text", ["", "abc", "-1", "nan", "inf", "1e400x", "+", "12 s"])
def test_time_point_rejects_nonsense(text: str) -> None:
    with pytest.raises(UsageError, match="invalid time"):
        TimePoint.parse(text)


def test_relative_time_resolves_against_the_log_start(sample_log: Path) -> None:
    log = open_log(sample_log)
    assert TimePoint.parse("+1.5").resolve(log) == T0_NS + 1_500_000_000
    assert TimePoint.parse("101.5").resolve(log) == T0_NS + 1_500_000_000


@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("2026-05-04T06:04:25Z", 1_777_874_665_000_000_000),
        ("2026-05-04T06:04:25.9z", 1_777_874_665_900_000_000),
        ("2026-05-04T08:04:25.000000001+02:00", 1_777_874_665_000_000_001),
        ("2026-05-04T01:04:25-0500", 1_777_874_665_000_000_000),
        ("2026-05-04 06:04", 1_777_874_640_000_000_000),  # no zone: UTC
    ],
)
def test_an_iso_time_names_the_utc_moment(text: str, ns: int) -> None:
    assert TimePoint.parse(text) == TimePoint(ns, wall=True)


def test_an_iso_time_is_refused_on_a_clock_that_tells_no_time_of_day(tmp_path: Path) -> None:
    from tests.trace_audit.conftest import write_log
    from trace_audit.log_time import NotWallClockError, resolve_time

    counting_from_zero = open_log(write_log(tmp_path / "zero.mcap"))  # "system", t = 100 s
    with pytest.raises(NotWallClockError, match="not times of day"):
        resolve_time("2026-05-04T06:04:25Z", counting_from_zero)
    wall = open_log(write_log(tmp_path / "wall.mcap", t0_ns=1_777_874_400 * 10**9))
    assert resolve_time("2026-05-04T06:00:01Z", wall) == 1_777_874_401 * 10**9


@given(st.integers(min_value=0, max_value=(1 << 63) - 1))
def test_a_printed_time_reads_back_to_the_same_nanosecond(t_ns: int) -> None:
    assert TimePoint.parse(exact_seconds(t_ns)).ns == t_ns
    wall = LogClock("system", EARLIEST_WALL_NS)
    if t_ns < 253_402_300_800 * 10**9:  # ISO years end at 9999
        assert TimePoint.parse(wall.arg(t_ns)).ns == t_ns


def test_a_wall_clock_time_is_shown_in_utc_with_seconds_since_the_start() -> None:
    clock = LogClock("system", 1_777_874_400 * 10**9)
    assert clock.show(1_777_874_665_900_000_000) == "2026-05-04T06:04:25.900Z (+265.900 s)"
    assert LogClock("sim", 0).show(265_900_000_000) == "265.900 s"
    assert not LogClock("system", 100 * 10**9).wall  # a system clock counting from zero
