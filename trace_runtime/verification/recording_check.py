"""The robot's recordings against the windows its chain sealed (profile 1.4): a message
changed, removed or added in a sealed window is a finding naming its recording, topic and
time; what the logger declared (a recording absent, stalled, unreadable), windows of a
recording that is not here, and messages recorded after the last sealed window are notes.

Each ``/trace/recording`` message is checked as the chain walk reads its cycle (only a cycle
whose seal holds: a modified one is already a finding), one window at a time, so memory stays
that of one window whatever the recording's size. Messages in a window's span that it does
not list wait until the walk ends, for a ``late`` entry of a later message that names them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from trace_runtime.clock import show_instant
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.errors import LogReadError
from trace_runtime.gaps import CycleRange
from trace_runtime.reading.recording_windows import Line, WindowDiff, compare_window, read_window
from trace_runtime.reading.recordings import Recordings
from trace_runtime.verification.sink import SegmentReporter

__all__ = ["RecordingCheck"]

_SHOWN = 5
"""Messages named in one finding; the rest are counted."""


@dataclass(slots=True)
class _Span:
    """How far the chain sealed one recording: its first and last window, how many."""

    start_ns: int
    end_ns: int
    windows: int = 0
    unchecked: int = 0
    where: CycleRange | None = None
    reporter: SegmentReporter | None = None


@dataclass(slots=True)
class RecordingCheck:
    """One robot's sealed recording windows, checked against ``recordings`` (None or a
    recording not among them: the windows are counted as unchecked, a note)."""

    recordings: Recordings | None
    spans: dict[str, _Span] = field(default_factory=dict)
    unlisted: dict[tuple[str, Line], tuple[SegmentReporter, CycleRange]] = field(
        default_factory=dict
    )
    late: set[tuple[str, Line]] = field(default_factory=set)
    windows: int = 0
    """Sealed windows read (in cycles whose seal holds)."""
    messages: int = 0
    """Recorded messages those windows seal."""
    checked: int = 0
    """Windows checked against a recording that is here."""
    _opened: dict[Path, McapFile] = field(default_factory=dict)

    def sealed(self, payload: bytes, where: CycleRange, report: SegmentReporter) -> None:
        """One ``/trace/recording`` message of a cycle whose seal holds."""
        try:
            value = orjson.loads(payload)
        except orjson.JSONDecodeError:
            return  # its seal holds, so the writer wrote it so; doctor names the schema break
        if not isinstance(value, dict):
            return
        for gap in _dicts(value.get("gaps")):
            report.note(
                "recording_gap",
                f"recording {gap.get('recording')}: {gap.get('state')} ({gap.get('detail')})",
                where,
            )
        for late in _dicts(value.get("late")):
            topic, t_ns, sequence = late.get("topic"), late.get("log_time_ns"), late.get("sequence")
            data = late.get("digest")
            if isinstance(topic, str) and type(t_ns) is int and type(sequence) is int:
                self.late.add((str(late.get("recording")), (topic, t_ns, sequence, str(data))))
        for window in _dicts(value.get("windows")):
            self._window(window, where, report)

    def _window(
        self, window: Mapping[str, Any], where: CycleRange, report: SegmentReporter
    ) -> None:
        name, start, end = window.get("recording"), window.get("start_ns"), window.get("end_ns")
        if not isinstance(name, str) or type(start) is not int or type(end) is not int:
            return
        span = self.spans.get(name)
        if span is None:
            span = self.spans[name] = _Span(start, end, where=where, reporter=report)
        span.start_ns, span.end_ns = min(span.start_ns, start), max(span.end_ns, end)
        span.windows += 1
        self.windows += 1
        count = window.get("count")
        self.messages += count if type(count) is int else 0
        files = self.recordings.files_of(name) if self.recordings is not None else ()
        if not files:
            span.unchecked += 1
            return
        try:
            actual = read_window(files, start, end, self._opened)
        except LogReadError as err:
            report.finding(
                "recording_modified",
                f"recording {name}: the window from {_t(start)} cannot be read ({err.reason})",
                where,
            )
            return
        self.checked += 1
        diff = compare_window(window, actual)
        for line in diff.added:
            self.unlisted[(name, line)] = (report, where)
        diff.added = []
        if diff:
            report.finding("recording_modified", _describe(name, start, end, diff), where)

    def finish(self) -> None:
        """After the walk: unlisted messages no late entry names are added ones; the notes
        for windows not checked and for messages after the last sealed window."""
        added: dict[str, list[tuple[Line, SegmentReporter, CycleRange]]] = {}
        for (name, line), (report, where) in self.unlisted.items():
            if (name, line) not in self.late:
                added.setdefault(name, []).append((line, report, where))
        for name, lines in added.items():
            lines.sort(key=lambda item: item[0][1])
            shown = ", ".join(f"{line[0]} at {_t(line[1])}" for line, _, _ in lines[:_SHOWN])
            more = f" and {len(lines) - _SHOWN} more" if len(lines) > _SHOWN else ""
            _, report, where = lines[0]
            report.finding(
                "recording_modified",
                f"recording {name}: {len(lines)} message(s) added in sealed windows: {shown}{more}",
                where,
            )
        for name, span in self.spans.items():
            self._span_notes(name, span)

    def _span_notes(self, name: str, span: _Span) -> None:
        report, where = span.reporter, span.where
        assert report is not None and where is not None
        if span.unchecked:
            why = (
                f"not found at {self.recordings.missing[name]}"
                if self.recordings is not None and name in self.recordings.missing
                else "not given"
            )
            report.note(
                "recording_unchecked",
                f"recording {name}: {span.unchecked} sealed window(s) not checked ({why})",
                where,
            )
            return
        files = self.recordings.files_of(name) if self.recordings is not None else ()
        try:
            before = read_window(files, 0, span.start_ns, self._opened)
            after = _count_after(files, span.end_ns, self._opened)
        except LogReadError:
            return  # a file that cannot be read was a finding of its window
        if before:
            report.finding(
                "recording_modified",
                f"recording {name}: {len(before)} message(s) before the first sealed window "
                f"({_t(span.start_ns)}), where the logger read none",
                where,
            )
        if after:
            report.note(
                "recording_unsealed",
                f"recording {name}: {after} message(s) from {_t(span.end_ns)} on, after the "
                "last window the chain sealed (recorded after the robot's last cycle, or within "
                "the sealing lag): not protected",
                where,
            )


def _count_after(files: tuple[Path, ...], start_ns: int, opened: dict[Path, McapFile]) -> int:
    count = 0
    for path in files:
        mcap = opened.get(path) or opened.setdefault(path, McapFile(path))
        count += sum(1 for _ in mcap.iter_messages(start_ns, None))
    return count


def _describe(name: str, start: int, end: int, diff: WindowDiff) -> str:
    parts: list[str] = []
    for label, items in (("changed", diff.changed), ("removed", diff.removed)):
        if items:
            shown = ", ".join(f"{topic} at {_t(t)}" for topic, t in items[:_SHOWN])
            more = f" and {len(items) - _SHOWN} more" if len(items) > _SHOWN else ""
            parts.append(f"{len(items)} {label}: {shown}{more}")
    for topic, (sealed, now) in diff.topics.items():
        parts.append(f"{topic}: {sealed} message(s) sealed, {now} now")
    if diff.forged and not parts:
        parts.append("the messages differ from the window's digest")
    return f"recording {name}, window {_t(start)} .. {_t(end)}: " + "; ".join(parts)


def _t(t_ns: int) -> str:
    """A recording's log time: its clock is not named, so a time of day when it can only be
    one (ROS time on a wall clock), else seconds."""
    return show_instant(t_ns, "system")


def _dicts(value: object) -> list[dict[str, Any]]:
    return [item for item in value if isinstance(item, dict)] if isinstance(value, list) else []
