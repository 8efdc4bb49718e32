"""The ``trace.session`` metadata record that opens every TRACE segment."""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, replace

from trace_runtime.records import GENESIS, PROFILE_VERSION

SESSION_METADATA = "trace.session"

TIER_METADATA = "trace.tier"
"""The metadata record a compacted segment carries: its source, whether it is lossy."""

EXCERPT_METADATA = "trace.excerpt"
"""The metadata record of a file cut from a robot's log at a cycle that began no segment (an
export of a window): ``source``, the segment it was cut from, and ``first_cycle``. Its chain
starts at the seal before that cycle (``trace.session`` ``prev_seal``), as a log whose
earlier segments retention removed starts at its first segment's."""

TIERS = ("hot", "warm", "cold")
"""The storage tiers, from the robot's own segments to the most compacted: the values of
``trace.session`` ``tier`` and the subdirectories of a log root (PROFILE section 9)."""

MIN_PERIOD_NS = 1_000
"""The shortest nominal period a reader accepts (1 us, a 1 MHz decision loop): a shorter one
is a corrupt or hostile record, and would make every nanosecond of jitter a gap."""
INT64_MAX = (1 << 63) - 1
"""Cycle numbers, segment numbers and periods are int64 in every writer (PROFILE section 2)."""

_ROBOT_ID = re.compile(r"[A-Za-z0-9_.-]+")
_DIGEST = re.compile(r"[0-9a-f]{64}")
_DECIMAL = re.compile(r"-?[0-9]{1,19}")
_RECORDING_NAME = re.compile(r"(?!\.\.?$)[^/\\\x00]{1,255}")
"""A recording's name: its folder's or file's name, so never a path nor ``.`` or ``..``."""


@dataclass(frozen=True, slots=True)
class SessionInfo:
    """Who wrote a segment, under which policy, and where it sits in the robot's chain."""

    robot_id: str
    period_ns: int
    software_version: str = ""
    policy_version: str = ""
    clock: str = "system"
    segment: int = 0
    prev_seal: str = GENESIS
    first_cycle: int = 0
    tier: str = "hot"
    profile_version: str = PROFILE_VERSION
    recordings: tuple[tuple[str, str], ...] = ()
    """The recordings the robot cites (profile 1.4): (name, path), the path relative to the
    log root (or to a single-file log's folder) where it lies below it, else absolute."""
    clock_step_from_ns: int | None = None
    """Set on a segment its writer began because the robot's clock stepped back (PROFILE
    section 4): the time of the last cycle before the step, so the step is declared, not
    mistaken for a restart or a gap. None on every other segment."""

    def to_metadata(self) -> dict[str, str]:
        """The MCAP metadata map (all values are strings, as MCAP requires); ``recordings``
        as a JSON object of name to path, left out when the robot cites none."""
        values = {
            key: str(value)
            for key, value in asdict(self).items()
            if key not in ("recordings", "clock_step_from_ns")
        }
        if self.clock_step_from_ns is not None:
            values["clock_step_from_ns"] = str(self.clock_step_from_ns)
        if self.recordings:
            values["recordings"] = json.dumps(dict(self.recordings), separators=(",", ":"))
        return values

    @classmethod
    def from_metadata(cls, data: dict[str, str]) -> SessionInfo:
        """Parse a metadata map; unknown keys are ignored so newer writers stay readable.

        Raises ``ValueError`` naming the key when a value is out of the profile's range (the
        reader wraps it as a ``LogReadError``): a robot id with other characters, a period
        under ``MIN_PERIOD_NS``, a negative or non-int64 segment or cycle number, a
        ``prev_seal`` that is not a digest."""
        robot_id = data.get("robot_id", "")
        if not _ROBOT_ID.fullmatch(robot_id):
            raise ValueError(
                f"robot_id {robot_id[:40]!r} is not a simple name (letters, digits, _.-)"
            )
        prev_seal = data.get("prev_seal", GENESIS)
        if not _DIGEST.fullmatch(prev_seal):
            raise ValueError(f"prev_seal {prev_seal[:40]!r} is not 64 lowercase hex digits")
        return cls(
            robot_id=robot_id,
            period_ns=_integer(data, "period_ns", None, MIN_PERIOD_NS),
            software_version=data.get("software_version", ""),
            policy_version=data.get("policy_version", ""),
            clock=data.get("clock", "system"),
            segment=_integer(data, "segment", 0, 0),
            prev_seal=prev_seal,
            first_cycle=_integer(data, "first_cycle", 0, 0),
            tier=data.get("tier", "hot"),
            profile_version=data.get("profile_version", PROFILE_VERSION),
            recordings=_recordings(data.get("recordings", "")),
            clock_step_from_ns=_step_from(data.get("clock_step_from_ns", "")),
        )

    def next_segment(
        self, prev_seal: str, first_cycle: int, clock_step_from_ns: int | None = None
    ) -> SessionInfo:
        """The session record of the segment that follows this one (``clock_step_from_ns``:
        it begins because the clock stepped back from that time)."""
        return replace(
            self,
            segment=self.segment + 1,
            prev_seal=prev_seal,
            first_cycle=first_cycle,
            clock_step_from_ns=clock_step_from_ns,
        )


def _recordings(text: str) -> tuple[tuple[str, str], ...]:
    """The ``recordings`` map's (name, path) pairs; entries that are not two strings are left
    out, as is the whole map when it is not a JSON object: a damaged pointer to evidence must
    not cost the investigator the segment (``doctor`` names it)."""
    if not text:
        return ()
    try:
        value = json.loads(text)
    except ValueError:
        return ()
    if not isinstance(value, dict):
        return ()
    return tuple(
        (name, path)
        for name, path in value.items()
        if isinstance(path, str) and _RECORDING_NAME.fullmatch(name) and path
    )


def _step_from(text: str) -> int | None:
    """A declared clock step's earlier time; None when absent or not a decimal int64 (a
    damaged declaration costs the note, not the segment: its cycles still verify)."""
    if not _DECIMAL.fullmatch(text):
        return None
    value = int(text)
    return value if 0 <= value <= INT64_MAX else None


def _integer(data: dict[str, str], key: str, default: int | None, low: int) -> int:
    """A decimal int64 value in ``[low, INT64_MAX]``; ``default`` when absent (None: required)."""
    text = data.get(key, "")
    if not text:
        if default is None:
            raise ValueError(f"{key} is missing")
        return default
    if not _DECIMAL.fullmatch(text):
        raise ValueError(f"{key} {text[:40]!r} is not a decimal integer")
    value = int(text)
    if not low <= value <= INT64_MAX:
        raise ValueError(f"{key} {value} is outside [{low}, {INT64_MAX}]")
    return value
