"""Durations as people type them (``90s``, ``30m``, ``24h``, ``7d``, ``2w``), in integer ns."""

from __future__ import annotations

import re

from trace_runtime.errors import UsageError

__all__ = ["DAY_NS", "SECOND_NS", "parse_duration"]

SECOND_NS = 1_000_000_000
DAY_NS = 86_400 * SECOND_NS

_UNITS = {"s": 1, "m": 60, "h": 3600, "d": 86_400, "w": 7 * 86_400}
_DURATION = re.compile(r"\s*(\d+(?:\.\d+)?)\s*([smhdw]?)\s*")


def parse_duration(text: str) -> int:
    """Nanoseconds in ``90s``, ``30m``, ``24h``, ``7d``, ``2w`` or a bare number of seconds."""
    match = _DURATION.fullmatch(text)
    if match is None:
        raise UsageError(f"bad duration {text!r}: use e.g. 90s, 30m, 24h, 7d, 2w or 0")
    return round(float(match.group(1)) * _UNITS[match.group(2) or "s"] * SECOND_NS)
