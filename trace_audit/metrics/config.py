"""How ``compute_metrics`` reads and scores a log: grouping, TCS weights, thresholds, limits.

Each value is checked when it is built, so a bad ``--by``, weight or threshold is a
``UsageError`` before any log is read.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from trace_audit.chains import DEFAULT_SENSOR_WINDOW
from trace_runtime.errors import UsageError
from trace_runtime.gaps import DEFAULT_GAP_TOLERANCE

__all__ = [
    "GROUP_BYS",
    "METRIC_NAMES",
    "GroupBy",
    "MetricsConfig",
    "TCSWeights",
    "parse_thresholds",
]

GroupBy = Literal["scenario", "segment", "robot", "hour"]
GROUP_BYS: tuple[str, ...] = get_args(GroupBy)


@dataclass(frozen=True, slots=True)
class TCSWeights:
    """Weights of the per-decision trust score TCS(d); they need not sum to 1."""

    et: float = 0.3
    et_partial: float = 0.1
    dr: float = 0.3
    continuity: float = 0.1
    integrity: float = 0.2
    integrity_gate: bool = True
    """TCS(d) = 0 when integrity fails: a record that may be altered earns no trust."""

    def __post_init__(self) -> None:
        values = (self.et, self.et_partial, self.dr, self.continuity, self.integrity)
        if any(v < 0 or not math.isfinite(v) for v in values) or sum(values) <= 0:
            raise UsageError("TCS weights must be finite, >= 0, and not all 0")

    @classmethod
    def parse(cls, text: str) -> TCSWeights:
        """Parse ``et=0.3,et_partial=0.1,dr=0.3,continuity=0.1,integrity=0.2,gate=1``."""
        values: dict[str, Any] = {}
        for item in _items(text):
            key, value = _split_pair(item, "TCS weight")
            key = key.lower()
            if key in ("gate", "integrity_gate"):
                if value.lower() not in ("0", "1", "true", "false", "on", "off"):
                    raise UsageError(f"TCS gate must be on or off, got {value!r}")
                values["integrity_gate"] = value.lower() in ("1", "true", "on")
            elif key in ("et", "et_partial", "dr", "continuity", "integrity"):
                values[key] = _number(value, f"TCS weight {key}")
            else:
                raise UsageError(
                    f"unknown TCS weight {key!r} "
                    "(use et, et_partial, dr, continuity, integrity, gate)"
                )
        return cls(**values)


METRIC_NAMES = ("ET", "ET_full", "ET_partial", "TC", "DR", "TCS")
"""Names ``--fail-under`` accepts: ET mean, share fully traceable, ET_partial, TC, DR, TCS."""


def parse_thresholds(text: str) -> dict[str, float]:
    """Parse ``ET=0.95,DR=95%`` into fractions; raise ``UsageError`` on anything else."""
    lookup = {name.lower(): name for name in METRIC_NAMES}
    out: dict[str, float] = {}
    for item in _items(text):
        key, value = _split_pair(item, "threshold")
        name = lookup.get(key.lower())
        if name is None:
            raise UsageError(
                f"unknown metric {key!r} in thresholds (use {', '.join(METRIC_NAMES)})"
            )
        if value.endswith("%"):
            number = _number(value[:-1], f"threshold {name}") / 100.0
        else:
            number = _number(value, f"threshold {name}")
            if number > 1.0:
                raise UsageError(f"threshold {name}={value} is above 1; write {value}% for percent")
        if not 0.0 <= number <= 1.0:
            raise UsageError(f"threshold {name}={value} is outside [0, 1]")
        out[name] = number
    return out


@dataclass(frozen=True, slots=True)
class MetricsConfig:
    """How ``compute_metrics`` reads and scores a log."""

    by: GroupBy | None = None
    gap_tolerance: float = DEFAULT_GAP_TOLERANCE
    """An interval between sealed cycles is a gap when > (1 + tolerance) x nominal period
    (the rule is ``trace_runtime.gaps``; this only overrides its tolerance)."""
    sensor_window: int = DEFAULT_SENSOR_WINDOW
    """Evidence refs resolve against this many cycles before the decision (and its own)."""
    weights: TCSWeights = field(default_factory=TCSWeights)
    thresholds: Mapping[str, float] = field(default_factory=dict)
    max_listed: int = 10_000
    """At most this many failing decisions and gaps are kept for listing (all are counted)."""
    workers: int = 1
    """Processes to spread segments over (1: in this process)."""
    start_ns: int | None = None
    end_ns: int | None = None
    evidence: tuple[str, ...] = ()
    """External recordings (MCAP files, rosbag2 directories) that evidence refs may name; a
    ref into one resolves there (digest checked), a ref into one not given does not."""

    def __post_init__(self) -> None:
        if self.by is not None and self.by not in GROUP_BYS:
            raise UsageError(f"cannot group by {self.by!r} (use {', '.join(GROUP_BYS)})")
        if not (self.gap_tolerance >= 0 and math.isfinite(self.gap_tolerance)):
            raise UsageError(f"gap tolerance must be >= 0, got {self.gap_tolerance}")
        if self.sensor_window < 0:
            raise UsageError(f"sensor window must be >= 0 cycles, got {self.sensor_window}")
        if self.workers < 1:
            raise UsageError(f"workers must be >= 1, got {self.workers}")
        if self.max_listed < 0:
            raise UsageError(f"max_listed must be >= 0, got {self.max_listed}")
        if self.start_ns is not None and self.end_ns is not None and self.end_ns < self.start_ns:
            raise UsageError("the analysis window ends before it starts")
        unknown = set(self.thresholds) - set(METRIC_NAMES)
        if unknown:
            raise UsageError(f"unknown metric(s) in thresholds: {', '.join(sorted(unknown))}")


# --- parsing NAME=VALUE lists ---------------------------------------------------------------


def _items(text: str) -> Iterator[str]:
    for raw in text.split(","):
        item = raw.strip()
        if item:
            yield item


def _split_pair(item: str, what: str) -> tuple[str, str]:
    if "=" not in item:
        raise UsageError(f"{what} {item!r} is not NAME=VALUE")
    key, value = item.split("=", 1)
    return key.strip(), value.strip()


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise UsageError(f"{what}: {text!r} is not a number") from err
    if not math.isfinite(value):
        raise UsageError(f"{what}: {text!r} is not a finite number")
    return value
