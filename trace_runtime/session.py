"""The ``trace.session`` metadata record that opens every TRACE segment."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

from trace_runtime.records import GENESIS, PROFILE_VERSION

SESSION_METADATA = "trace.session"


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

    def to_metadata(self) -> dict[str, str]:
        """The MCAP metadata map (all values are strings, as MCAP requires)."""
        return {key: str(value) for key, value in asdict(self).items()}

    @classmethod
    def from_metadata(cls, data: dict[str, str]) -> SessionInfo:
        """Parse a metadata map; unknown keys are ignored so newer writers stay readable."""
        return cls(
            robot_id=data.get("robot_id", ""),
            period_ns=int(data.get("period_ns", "0") or 0),
            software_version=data.get("software_version", ""),
            policy_version=data.get("policy_version", ""),
            clock=data.get("clock", "system"),
            segment=int(data.get("segment", "0") or 0),
            prev_seal=data.get("prev_seal", GENESIS),
            first_cycle=int(data.get("first_cycle", "0") or 0),
            tier=data.get("tier", "hot"),
            profile_version=data.get("profile_version", PROFILE_VERSION),
        )

    def next_segment(self, prev_seal: str, first_cycle: int) -> SessionInfo:
        """The session record of the segment that follows this one."""
        return replace(self, segment=self.segment + 1, prev_seal=prev_seal, first_cycle=first_cycle)
