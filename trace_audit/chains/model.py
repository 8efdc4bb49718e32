"""What a decision's factor chains are: the levels of a chain (``LEVELS``), the depth each
kind of factor is expected to reach, one link, one factor's chain, every chain of a
decision with its ET / ET_partial (``DecisionChains``), and the numbers alone
(``DecisionScore``). The walk that builds them is ``chains.walk``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

__all__ = [
    "EXPECTED_DEPTH_ENTITY",
    "EXPECTED_DEPTH_STATE",
    "LEVELS",
    "DecisionChains",
    "DecisionScore",
    "FactorChain",
    "Link",
]

LEVELS = ("factor_node", "belief_path", "entity", "evidence_ref", "sensor_reading")
EXPECTED_DEPTH_STATE = 5
EXPECTED_DEPTH_ENTITY = 4


@dataclass(frozen=True, slots=True)
class Link:
    """One level of a factor's chain: what it points at, and whether the log documents it."""

    level: str
    documented: bool
    ref: str
    detail: str = ""
    unknown: bool = False
    """Not documented because the external recording holding the reading could not be
    read: whether it resolves is unknown, not false."""


@dataclass(frozen=True, slots=True)
class FactorChain:
    """The documented chain of one factor of a decision."""

    node: str
    name: str
    links: tuple[Link, ...]
    depth: int
    expected_depth: int

    @property
    def traceable(self) -> bool:
        return self.depth == self.expected_depth

    @property
    def partial(self) -> float:
        return self.depth / self.expected_depth

    @property
    def unknown(self) -> bool:
        """Whether the chain is traceable is unknown: it stops only at a reading in an
        external recording that could not be read."""
        missing = self.missing
        return missing is not None and missing.unknown

    @property
    def missing(self) -> Link | None:
        """The first missing link (where the chain breaks), or None when traceable."""
        for link in self.links:
            if not link.documented:
                return link
        return None


@dataclass(frozen=True, slots=True)
class DecisionChains:
    """Every factor chain of one decision and its ET / ET_partial.

    A decision whose action is not logged, or names no factor, has ET = ET_partial = 0:
    nothing links it to evidence (``reason`` says which).
    """

    cycle: int
    t_ns: int
    factors: tuple[FactorChain, ...]
    et: float
    et_partial: float
    reason: str = ""

    @property
    def fully_traceable(self) -> bool:
        return bool(self.factors) and all(f.traceable for f in self.factors)

    @property
    def unknown(self) -> bool:
        """ET is unknown: a factor's chain stops at a recording that could not be read."""
        return any(f.unknown for f in self.factors)

    @property
    def known_et(self) -> float | None:
        """ET, or None when it is unknown (``unknown``)."""
        return None if self.unknown else self.et

    @property
    def known_et_partial(self) -> float | None:
        """ET_partial, or None when ET is unknown."""
        return None if self.unknown else self.et_partial


class DecisionScore(NamedTuple):
    """ET numbers of one decision without the links (what metrics need per cycle)."""

    et: float
    et_partial: float
    factors: int
    traceable: int
    reason: str
    unknown: int = 0
    """Factors whose chain stops only at a reading in an external recording that could not
    be read: while any is, the decision's ET and ET_partial are unknown, not these."""

    @property
    def fully_traceable(self) -> bool:
        return self.factors > 0 and self.traceable == self.factors

    @property
    def known(self) -> bool:
        """ET and ET_partial are known (no factor's evidence is in an unreadable recording)."""
        return not self.unknown
