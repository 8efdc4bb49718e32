"""What ``doctor`` reports: the rules of PROFILE.md it checks, and the problems it found.

Every problem names one rule; a rule names the PROFILE section it comes from and whether the
profile says MUST (the log does not conform: exit 1) or SHOULD (a note: exit 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

__all__ = ["RULES", "DoctorReport", "Level", "Problem", "Rule", "SegmentDoctor"]

Level = Literal["MUST", "SHOULD"]


@dataclass(frozen=True, slots=True)
class Rule:
    """One requirement of the profile: an id, the section it is written in, its level."""

    id: str
    section: str
    level: Level
    text: str


def _rules(*rows: tuple[str, str, Level, str]) -> dict[str, Rule]:
    return {row[0]: Rule(*row) for row in rows}


RULES = _rules(
    # §1 files and segments
    ("header-profile", "§1", "MUST", "the MCAP Header's profile is 'trace'"),
    ("chunk-compression", "§1", "SHOULD", "chunks are zstd-compressed"),
    ("chunk-order", "§1", "MUST", "chunks are written in time order"),
    (
        "summary",
        "§1",
        "MUST",
        "a closed segment carries the MCAP summary: Schema, Channel, "
        "Statistics, Chunk Index, Metadata Index and Summary Offset records",
    ),
    ("summary-agrees", "§1", "MUST", "the summary's statistics and indexes describe the data"),
    (
        "closed",
        "§1",
        "SHOULD",
        "a segment is closed (footer and summary); an unclosed one is read by a scan",
    ),
    # §2 session metadata
    ("session", "§2", "MUST", "one trace.session metadata record, before the first chunk"),
    ("session-values", "§2", "MUST", "trace.session values are in the profile's ranges"),
    ("session-keys", "§2", "SHOULD", "trace.session carries every key of the table"),
    # §3 channels
    (
        "channel-schema",
        "§3",
        "MUST",
        "a /trace channel has the schema named in the table, schema encoding 'jsonschema'",
    ),
    (
        "message-encoding",
        "§3",
        "MUST",
        "/trace channels use message encoding 'json' in the hot tier",
    ),
    ("sensor-encoding", "§3", "SHOULD", "sensor channels use message encoding 'json'"),
    (
        "known-channel",
        "§3",
        "SHOULD",
        "/trace topics are those of the table (readers ignore others)",
    ),
    ("one-per-cycle", "§3", "MUST", "a cycle has at most one message per layer channel"),
    # §4 time and cycle numbers
    ("stamp", "§4", "MUST", "every /trace message carries integer cycle and t_ns"),
    ("log-time", "§4", "MUST", "MCAP log_time and publish_time equal the message's t_ns"),
    ("sequence", "§4", "MUST", "MCAP sequence equals the message's cycle"),
    ("same-cycle", "§4", "MUST", "all of a cycle's /trace messages have the same cycle and t_ns"),
    ("cycle-order", "§4", "MUST", "cycle numbers increase from cycle to cycle"),
    ("time-order", "§4", "MUST", "t_ns does not decrease from cycle to cycle within a segment"),
    # §5 one cycle in the file
    ("cycle-layout", "§5", "MUST", "a cycle's messages are sensors, then layers, then the seal"),
    ("cycle-in-chunk", "§5", "SHOULD", "all of a cycle's messages are in one chunk"),
    ("sealed", "§5", "MUST", "a closed segment has no layer messages after its last seal"),
    # §6 canonical bytes, seals, checkpoints
    (
        "compact-json",
        "§6",
        "MUST",
        "/trace message data is compact UTF-8 JSON, no BOM, unique keys",
    ),
    ("schema-valid", "§6", "MUST", "each /trace message is valid against its JSON Schema"),
    (
        "seal-chain",
        "§6",
        "MUST",
        "each seal names its layer messages' digests (from 1.3 its sensor readings too) and "
        "the previous seal",
    ),
    (
        "seal-sensors",
        "§6",
        "MUST",
        "from profile 1.3, each seal covers its cycle's sensor readings ('sensors')",
    ),
    ("checkpoint", "§6", "MUST", "a checkpoint names the chain head it claims"),
    (
        "checkpoint-cadence",
        "§6",
        "SHOULD",
        "a checkpoint at most every 10 s of log time and a final one at close",
    ),
    # §7 dropped cycles
    (
        "declared-drops",
        "§7",
        "MUST",
        "cycles not written are declared in the next seal's 'dropped'",
    ),
    # §8 evidence refs
    ("evidence-digest", "§8", "MUST", "a sensor message an evidence ref names matches its digest"),
    ("evidence-resolves", "§8", "SHOULD", "every evidence ref resolves to a logged sensor message"),
    ("readable", "§8", "MUST", "every chunk decodes (damage is reported, not read past)"),
    # §11 external recordings
    (
        "external-digest",
        "§11",
        "MUST",
        "a message an external ref names is in the recording and matches its digest",
    ),
    (
        "external-given",
        "§11",
        "SHOULD",
        "external recordings the refs name are checked (doctor --evidence)",
    ),
)


@dataclass(frozen=True, slots=True)
class Problem:
    """One place where a segment breaks a rule: which rule, where, and what was seen."""

    rule: str
    section: str
    level: Level
    message: str
    cycle: int | None = None
    offset: int | None = None
    """File offset of the record (for a message inside a chunk: the chunk's offset)."""
    count: int = 1
    """How many times the same rule broke the same way (only the first is located)."""
    key: str = ""
    """What makes two problems of a rule "the same way" (e.g. the topic)."""
    last_cycle: int | None = None
    """The last cycle of a problem that spans a run of cycles (e.g. refs into a recording
    cut short), else ``cycle``."""


@dataclass(slots=True)
class SegmentDoctor:
    """Problems of one segment file, and what was looked at."""

    path: str
    robot: str | None = None
    """The robot whose segment it is (its ``trace.session``, else its file name), None when
    neither says."""
    problems: list[Problem] = field(default_factory=list)
    messages: int = 0
    cycles: int = 0
    summarised: int = 0
    """Warm summaries read: their pruned layers are checked for stamps and order only."""
    chunks: int = 0
    closed: bool = False
    conforms: bool = True
    """No MUST broken (kept up to date by ``add``)."""

    def add(
        self,
        rule: str,
        message: str,
        *,
        cycle: int | None = None,
        offset: int | None = None,
        key: str | None = None,
        last_cycle: int | None = None,
    ) -> None:
        """Record a problem. The same rule broken the same way again (same ``key``, by default
        the same message) only counts up: the first place is the one reported."""
        spec = RULES[rule]
        key = message if key is None else key
        for i, seen in enumerate(self.problems):
            if seen.rule == rule and seen.key == key:
                self.problems[i] = Problem(
                    rule, spec.section, spec.level, seen.message, seen.cycle, seen.offset,
                    seen.count + 1, key, seen.last_cycle,
                )  # fmt: skip
                return
        last = cycle if last_cycle is None else last_cycle
        self.problems.append(
            Problem(rule, spec.section, spec.level, message, cycle, offset, 1, key, last)
        )
        if spec.level == "MUST":
            self.conforms = False


@dataclass(slots=True)
class DoctorReport:
    """The result of ``doctor_log``: per segment, the rules it breaks (MUST) and the notes
    (SHOULD); ``conforms`` is False when any MUST is broken."""

    path: str
    segments: list[SegmentDoctor] = field(default_factory=list)
    rules_checked: int = len(RULES)
    evidence: list[str] = field(default_factory=list)
    """External recordings given (file names), against which external refs were checked."""
    conforms: bool = True
    """No segment breaks a MUST (set by ``doctor_log`` when it is done)."""

    @property
    def errors(self) -> list[Problem]:
        return [p for _, p in self.located("MUST")]

    @property
    def notes(self) -> list[Problem]:
        return [p for _, p in self.located("SHOULD")]

    @property
    def robots(self) -> list[str]:
        """The robots whose segments were checked, sorted."""
        return sorted({s.robot for s in self.segments if s.robot is not None})

    def located(self, level: Level) -> list[tuple[SegmentDoctor, Problem]]:
        """The problems of ``level``, each with the segment it was found in, in file order."""
        return [(s, p) for s in self.segments for p in s.problems if p.level == level]
