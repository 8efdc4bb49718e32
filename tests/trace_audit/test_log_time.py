"""log_time: a time given at the CLI is read exactly, and a relative one against the log start."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.conftest import T0_NS
from trace_audit.log_time import TimePoint
from trace_runtime import open_log
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
