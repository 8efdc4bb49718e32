"""Where the checks put what they find: the findings (a modified seal seen from both sides
of its link once), the notes, and the count of cycles the logger declared dropped; and the
``SegmentReporter`` that locates each one in the segment it is about."""

from __future__ import annotations

from trace_runtime.gaps import NOWHERE, CycleRange
from trace_runtime.verification.report import Finding, FindingKind, NoteKind

__all__ = ["FindingSink", "SegmentReporter"]


class FindingSink:
    """Collects findings and notes for one verification (or one robot's part of it)."""

    def __init__(self) -> None:
        self.findings: list[Finding] = []
        self.notes: list[Finding] = []
        self.declared = 0
        self._seen: set[tuple[str, str, str, int | None, int | None]] = set()

    def finding(self, f: Finding) -> None:
        key = (f.kind, f.robot_id, f.segment, f.where.first_cycle, f.where.last_cycle)
        if f.kind == "modified" and key in self._seen:
            return  # a modified seal is seen from both sides of its link: report it once
        self._seen.add(key)
        self.findings.append(f)

    def note(self, f: Finding) -> None:
        self.notes.append(f)

    def quiet(self) -> FindingSink:
        """A sink that shares this one's findings and drops notes and counts."""
        other = FindingSink()
        other.findings = self.findings
        other._seen = self._seen
        return other


class SegmentReporter:
    """Files findings and notes under one segment: its robot, display name and number."""

    __slots__ = ("name", "number", "robot_id", "sink")

    def __init__(self, sink: FindingSink, robot_id: str, name: str, number: int) -> None:
        self.sink = sink
        self.robot_id = robot_id
        self.name = name
        self.number = number

    def finding(self, kind: FindingKind, message: str, where: CycleRange = NOWHERE) -> None:
        self.sink.finding(self._located(kind, message, where))

    def note(self, kind: NoteKind, message: str, where: CycleRange = NOWHERE) -> None:
        self.sink.note(self._located(kind, message, where))

    def _located(self, kind: FindingKind | NoteKind, message: str, where: CycleRange) -> Finding:
        return Finding(
            kind=kind,
            message=message,
            robot_id=self.robot_id,
            segment=self.name,
            segment_no=self.number,
            where=where,
        )
