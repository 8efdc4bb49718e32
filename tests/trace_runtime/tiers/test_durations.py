"""Durations as people type them, in integer nanoseconds."""

from __future__ import annotations

import pytest

from trace_runtime.tiers import parse_duration
from trace_runtime.tiers.durations import DAY_NS


def test_parse_duration() -> None:
    assert parse_duration("24h") == 24 * 3600 * 10**9
    assert parse_duration("7d") == 7 * DAY_NS
    assert parse_duration("90s") == parse_duration("1.5m") == 90 * 10**9
    assert parse_duration("0") == 0
    for bad in ("", "h", "-1h", "3 days", "1y"):
        with pytest.raises(Exception, match="bad duration"):
            parse_duration(bad)
