"""What every answer of the assistant carries: its integrity, the command that reproduces it,
what was cut to keep it bounded, and the data (``trace-audit <command> --json``'s).

The models are the tools' output schemas: their field descriptions are what a model reads
to know what an answer means, so they say it plainly.
"""

from __future__ import annotations

from typing import Generic, Literal, TypeVar

from pydantic import BaseModel, Field

__all__ = [
    "Answer",
    "Integrity",
    "IntegrityFinding",
    "IntegrityScope",
    "IntegrityStatus",
    "Truncation",
]

T = TypeVar("T")

IntegrityStatus = Literal["verified", "unverified", "integrity_failed"]


class IntegrityFinding(BaseModel):
    """One problem ``trace-audit verify`` found in the log the answer rests on."""

    kind: str = Field(description="The finding's kind, e.g. seal_mismatch, chain_break.")
    robot: str = Field(description="The robot whose chain it is in ('' when not one robot's).")
    segment: str = Field(description="The segment file it is in ('' when not one file's).")
    first_cycle: int | None = Field(description="First cycle it covers (null: not located).")
    last_cycle: int | None = Field(description="Last cycle it covers (null: not located).")
    message: str = Field(description="What verify says of it.")


class IntegrityScope(BaseModel):
    """What the integrity status rests on."""

    source: str = Field(description="The log (or fleet index) the answer was read from.")
    robots: list[str] = Field(description="The robots whose chains the status covers.")
    segments: int = Field(description="Segment files verify read.")
    cycles: int = Field(description="Sealed cycles verify read.")
    cycles_valid: int = Field(description="Of them, cycles whose messages match their seal.")
    signatures_checked: bool = Field(
        description="Whether checkpoint signatures were checked with the robot's key (the "
        "server was started with --key): when false, verified says the log is consistent "
        "with itself, not who wrote it, and the summary says signatures were not checked."
    )
    witness_checked: bool = Field(
        description="Whether the log was compared with its root's witness store, each "
        "cosignature checked with the witness's key (the server was started with "
        "--witness-key)."
    )
    witnessed: int = Field(
        description="Checkpoints of these robots the witness cosigned (its key checked) "
        "that the log agrees with (0 without --witness-key)."
    )
    cached: bool = Field(
        description="True when this verify was run earlier in this server on the same "
        "files (same names, sizes and modification times), not again for this answer."
    )


class Integrity(BaseModel):
    """Whether the data the answer rests on is intact."""

    status: IntegrityStatus = Field(
        description="verified: trace-audit verify found no problem in the chains of the "
        "robots the answer is about (every cycle matches its seal, no cycle missing or "
        "reordered, checkpoints consistent; with the server's --key, checkpoints signed by "
        "the robot's key, and with --witness-key, agreeing with what its witness cosigned: "
        "scope says which were checked). integrity_failed: it found at least one "
        "(listed in findings): the log was changed or damaged after it was written, so "
        "treat the answer as unreliable and say so. unverified: the answer could not be "
        "checked (the summary says why: an index answer, a listing, or verify ran out of "
        "time)."
    )
    summary: str = Field(description="One line to tell the user, beginning with the status.")
    findings: list[IntegrityFinding] = Field(
        description="The first findings, in the log's order (findings_total counts all)."
    )
    findings_total: int = Field(description="How many findings verify reported in all.")
    scope: IntegrityScope | None = Field(
        description="What the status covers (null when nothing was verified)."
    )


class Truncation(BaseModel):
    """A list cut to keep the answer within the server's size bound."""

    path: str = Field(description="Where in data, e.g. robots[0].transitions.")
    robot: str | None = Field(
        None,
        description="The robot whose items were cut (null: the list is not one robot's). "
        "An answer about several robots is cut evenly: each robot keeps its share.",
    )
    kept: int = Field(description="Items kept (the robot's first ones).")
    total: int = Field(description="Items the full answer has (of that robot).")
    through: str | None = Field(
        None,
        description="Where the kept items end: the last one's cycle and time, the time as "
        "start or end take it (null: the items have no time).",
    )
    rest: str = Field("", description="How to ask for the items left out.")


class Answer(BaseModel, Generic[T]):
    """An answer: integrity first, then how to reproduce it, then the data."""

    integrity: Integrity = Field(description="Read this first: whether the data is intact.")
    reproduce: str = Field(
        description="The trace-audit command line that prints the same data (its --json), "
        "for the user to run and check."
    )
    truncated: list[Truncation] = Field(
        description="Lists cut to bound the answer's size (empty: nothing was cut). Narrow "
        "the question (a robot, a time, a window) or run the reproduce command for all."
    )
    data: T | None = Field(
        description="The data of trace-audit's --json for the same question (null only when "
        "even cut it would not fit)."
    )
