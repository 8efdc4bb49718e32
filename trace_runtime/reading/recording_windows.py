"""A recording's messages in windows of log time: how a window is sealed, and how a sealed
window is checked against the recording as it is now (profile 1.4).

The writer (``logger.recording_seals``) and the verifier (``verification.recording_check``)
meet here, so the bytes one digests are the bytes the other does. A window's messages are
taken in a canonical order (log time, topic, sequence, data digest), not in file order: a
recording's split files, chunks and the order its writer flushed them do not matter, only
which messages there are. A window lists each message (topic, time, sequence and the first
16 hex digits of its data digest) when it holds at most ``MAX_LISTED`` of them, so that a
verifier can say which message changed, went or came; the window's full digest decides.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trace_runtime.chain import sensor_cover, sensor_line
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits

__all__ = [
    "MAX_LISTED",
    "Line",
    "WindowDiff",
    "compare_window",
    "line_of",
    "read_window",
    "seal_window",
]

MAX_LISTED = 4096
"""The most messages a window lists one by one; a busier window is sealed by its digest and
its count per topic alone (a change is then found, and named by topic and window)."""

PREFIX = 16
"""Hex digits of a message's data digest a window lists: enough to tell which message
changed; the window's full digest is what a forgery would have to match."""

Line = tuple[str, int, int, str]
"""One recorded message as a window covers it: (topic, log time ns, sequence, data digest)."""


def line_of(message: RawMessage) -> Line:
    """What a window covers of one message (its data by SHA-256)."""
    data_digest = hashlib.sha256(message.data).hexdigest()
    return message.topic, message.log_time_ns, message.sequence, data_digest


def _order(line: Line) -> tuple[int, str, int, str]:
    topic, t_ns, sequence, data_digest = line
    return t_ns, topic, sequence, data_digest


def window_digest(lines: Iterable[Line]) -> str:
    """SHA-256 hex over the messages' sensor lines (PROFILE §6) in the canonical order."""
    ordered = sorted(lines, key=_order)
    return sensor_cover([sensor_line(topic, seq, t, d) for topic, t, seq, d in ordered])[1]


def seal_window(recording: str, start_ns: int, end_ns: int, lines: list[Line]) -> dict[str, Any]:
    """The ``RecordingWindow`` (as JSON, in its schema's field order) of ``lines``, the
    messages of ``recording`` with log time in ``[start_ns, end_ns)``."""
    ordered = sorted(lines, key=_order)
    topics = Counter(line[0] for line in ordered)
    listed = (
        [[topic, t, seq, d[:PREFIX]] for topic, t, seq, d in ordered]
        if len(ordered) <= MAX_LISTED
        else None
    )
    return {
        "recording": recording,
        "start_ns": start_ns,
        "end_ns": end_ns,
        "count": len(ordered),
        "digest": window_digest(ordered),
        "topics": dict(sorted(topics.items())),
        "messages": listed,
    }


def read_window(
    files: Sequence[Path],
    start_ns: int,
    end_ns: int,
    opened: dict[Path, McapFile] | None = None,
    limits: ReadLimits = DEFAULT_LIMITS,
) -> list[Line]:
    """The messages with log time in ``[start_ns, end_ns)`` in every file of a recording, as
    they are now (each file's chunk index where it has one; ``opened`` keeps files open
    between windows)."""
    found: list[Line] = []
    if end_ns <= start_ns:
        return found
    cache = {} if opened is None else opened
    for path in files:
        mcap = cache.get(path)
        if mcap is None:
            mcap = cache[path] = McapFile(path, limits)
        found.extend(line_of(m) for m in mcap.iter_messages(start_ns, end_ns - 1))
    return found


@dataclass(slots=True)
class WindowDiff:
    """What differs between a sealed window and the recording: each as (topic, log time)."""

    changed: list[tuple[str, int]] = field(default_factory=list)
    removed: list[tuple[str, int]] = field(default_factory=list)
    added: list[Line] = field(default_factory=list)
    """Messages the window does not list (added, or written late: ``RecordingLate``)."""
    forged: bool = False
    """Every listed message is there, but the window's digest differs (a message forged to
    the listed prefix), or the window lists none and its count or digest differs."""
    topics: dict[str, tuple[int, int]] = field(default_factory=dict)
    """For a window that lists no messages: topics whose count differs (sealed, now)."""

    def __bool__(self) -> bool:
        return bool(self.changed or self.removed or self.added or self.forged or self.topics)


def compare_window(window: Mapping[str, Any], actual: list[Line]) -> WindowDiff:
    """Compare a sealed window (``RecordingWindow`` JSON) with the messages now in its span.
    Messages not listed are returned in ``added`` for the caller to match against late ones;
    the digest is then checked over the messages the window did list."""
    diff = WindowDiff()
    listed = window.get("messages")
    if not isinstance(listed, list):
        return _compare_unlisted(window, actual, diff)
    expected: dict[tuple[str, int, int], list[str]] = {}
    for entry in listed:
        topic, t_ns, sequence, prefix = entry
        expected.setdefault((topic, t_ns, sequence), []).append(prefix)
    kept: list[Line] = []
    for line in actual:
        key = (line[0], line[1], line[2])
        prefixes = expected.get(key)
        if prefixes and line[3][:PREFIX] in prefixes:
            prefixes.remove(line[3][:PREFIX])
            kept.append(line)
        elif prefixes:
            prefixes.pop(0)
            diff.changed.append((line[0], line[1]))
        else:
            diff.added.append(line)
    diff.removed = [(k[0], k[1]) for k, left in expected.items() for _ in left]
    if not (diff.changed or diff.removed) and window_digest(kept) != window.get("digest"):
        diff.forged = True
    return diff


def _compare_unlisted(
    window: Mapping[str, Any], actual: list[Line], diff: WindowDiff
) -> WindowDiff:
    if len(actual) == window.get("count") and window_digest(actual) == window.get("digest"):
        return diff
    now = Counter(line[0] for line in actual)
    sealed = window.get("topics") if isinstance(window.get("topics"), dict) else {}
    assert isinstance(sealed, dict)
    for topic in sorted(set(now) | set(sealed)):
        before = sealed.get(topic, 0)
        if before != now.get(topic, 0):
            diff.topics[topic] = (before if isinstance(before, int) else -1, now.get(topic, 0))
    diff.forged = not diff.topics
    return diff
