"""The robot's recordings followed on the writer thread, so that every message recorded in
them is sealed into its chain, cited or not (profile 1.4, ``recording_records``).

A recording (a rosbag2 folder whose split files appear one after another, or one MCAP file)
is written by another process, ``ros2 bag record``, at its own pace and in chunks. Each
``RecordingFollower`` reads only what was appended since its last poll
(``reading.growing_mcap``), keeps the messages of the windows of log time not yet sealed, and
seals a window once the recording has gone ``settle`` past its end (its recorder writes in
time order, so nothing more should land in it) or has not grown for ``settle`` of wall time
(the recorder stopped, or waits to fill a chunk): then it seals what it has up to its newest
message, and what lands next, being newer, opens the next window.
A message that lands in a window already sealed is sealed on its own (``late``). A recording
that is not there, stops growing or cannot be read is declared (``gaps``), never hidden.

What it keeps is bounded: the messages of the windows still open, one ``GrowingMcap`` per
file, and at most ``MAX_WINDOWS`` windows handed out per poll (a long backlog, such as a
recording that ran before the robot, is sealed over several batches).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson

from trace_runtime.errors import LogReadError
from trace_runtime.logger.config import LoggerConfig
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.reading.growing_mcap import GrowingMcap
from trace_runtime.reading.recording_windows import Line, line_of, seal_window
from trace_runtime.reading.recordings import recording_files
from trace_runtime.session import SessionInfo

__all__ = [
    "POLL_S",
    "RecordingBatch",
    "RecordingFollower",
    "RecordingSeals",
    "encode_recording_seal",
]

POLL_S = 0.5
"""How often the writer looks at the recordings (at its next batch after this long)."""
MAX_WINDOWS = 64
"""Windows handed out per poll: bounds one ``/trace/recording`` message."""


@dataclass(slots=True)
class RecordingBatch:
    """What the next ``/trace/recording`` message carries."""

    windows: list[dict[str, Any]] = field(default_factory=list)
    late: list[dict[str, Any]] = field(default_factory=list)
    gaps: list[dict[str, Any]] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.windows or self.late or self.gaps)

    def full(self) -> bool:
        return len(self.windows) >= MAX_WINDOWS


class RecordingFollower:
    """One recording, followed: its files as they appear, its windows as they fill."""

    def __init__(
        self,
        name: str,
        path: Path,
        *,
        window_ns: int,
        settle_ns: int,
        limits: ReadLimits = DEFAULT_LIMITS,
    ) -> None:
        self.name, self.path = name, path
        self._window_ns, self._settle_ns, self._limits = window_ns, settle_ns, limits
        self._idle_s = settle_ns / 1e9
        self._files: dict[Path, GrowingMcap] = {}
        self._broken: set[Path] = set()
        self._pending: list[Line] = []
        self._sealed_to: int | None = None  # every log time below this is sealed
        self._newest: int | None = None
        self._last_growth = time.monotonic()
        self._state = "new"  # new | absent | growing | stalled

    def poll(self, out: RecordingBatch, now: float) -> None:
        """Read what was appended and hand out the windows, late messages and gaps due."""
        files = recording_files(self.path)
        if not files:
            if self._state in ("new",):
                self._gap(out, "absent", "nothing recorded at its declared path yet")
                self._state = "absent"
            return
        grew = self._read(files, out)
        if grew:
            self._last_growth = now
            if self._state in ("absent", "stalled"):
                why = "it appeared" if self._state == "absent" else "it grows again"
                self._gap(out, "resumed", why)
            self._state = "growing"
        elif now - self._last_growth >= self._idle_s:
            if self._pending and not out.full():
                self._seal(out, self._newest + 1 if self._newest is not None else 0)
            if self._state == "growing":
                self._gap(out, "stalled", f"no new message for {self._idle_s:g} s")
                self._state = "stalled"

    def _read(self, files: list[Path], out: RecordingBatch) -> bool:
        grew = False
        for path in files:
            if path in self._broken:
                continue
            follower = self._files.get(path)
            if follower is None:
                follower = self._files[path] = GrowingMcap(path, self._limits)
            try:
                for messages in follower.poll_records():
                    grew = True
                    self._take(messages, out)
                    self._seal_due(out)
                    if out.full():
                        return grew
            except LogReadError as err:  # LogLimitError too: the file is not followed further
                self._broken.add(path)
                self._gap(out, "unreadable", f"{path.name}: {err.reason}")
        return grew

    def _take(self, messages: list[Any], out: RecordingBatch) -> None:
        sealed_to = self._sealed_to
        for message in messages:
            line = line_of(message)
            t_ns = line[1]
            if self._newest is None or t_ns > self._newest:
                self._newest = t_ns
            if sealed_to is not None and t_ns < sealed_to:
                out.late.append(
                    {
                        "recording": self.name,
                        "topic": line[0],
                        "log_time_ns": t_ns,
                        "sequence": line[2],
                        "digest": line[3],
                    }
                )
            else:
                self._pending.append(line)

    def _seal_due(self, out: RecordingBatch) -> None:
        """Seal each window the recording has gone ``settle`` past."""
        newest = self._newest
        while self._pending and newest is not None and not out.full():
            # The window holding the earliest open message (stretches without one join it).
            first = min(line[1] for line in self._pending)
            end = (first // self._window_ns + 1) * self._window_ns
            if newest < end + self._settle_ns:
                return
            self._seal(out, end)

    def _start(self) -> int:
        if self._sealed_to is not None:
            return self._sealed_to
        first = min(line[1] for line in self._pending)
        return first // self._window_ns * self._window_ns

    def _seal(self, out: RecordingBatch, end: int) -> None:
        """Hand out the window from where sealing stands up to ``end`` (an empty stretch
        joins the next window that holds a message, so windows stay contiguous)."""
        start = self._start()
        inside = [line for line in self._pending if line[1] < end]
        self._pending = [line for line in self._pending if line[1] >= end]
        out.windows.append(seal_window(self.name, start, end, inside))
        self._sealed_to = end

    def _gap(self, out: RecordingBatch, state: str, detail: str) -> None:
        out.gaps.append({"recording": self.name, "state": state, "detail": detail})


class RecordingSeals:
    """Every recording a robot cites, followed; ``collect`` gives the next
    ``/trace/recording`` fields, kept until a batch carrying them is written."""

    def __init__(
        self,
        recordings: tuple[tuple[str, str], ...],
        base: Path,
        *,
        window_s: float,
        settle_s: float,
        report_once: Callable[[str, str], None],
    ) -> None:
        window_ns, settle_ns = max(1, round(window_s * 1e9)), max(0, round(settle_s * 1e9))
        self._followers = [
            RecordingFollower(name, base / where, window_ns=window_ns, settle_ns=settle_ns)
            for name, where in recordings
        ]
        self._out = RecordingBatch()
        self._last_poll = -POLL_S
        self._report_once = report_once

    @classmethod
    def declared(
        cls,
        session: SessionInfo,
        base: Path,
        config: LoggerConfig,
        report_once: Callable[[str, str], None],
    ) -> RecordingSeals | None:
        """The followers of the recordings ``session`` declares (paths relative to
        ``base``); None when it declares none."""
        if not session.recordings:
            return None
        return cls(
            session.recordings,
            base,
            window_s=config.recording_window_s,
            settle_s=config.recording_settle_s,
            report_once=report_once,
        )

    def collect(self) -> RecordingBatch | None:
        """What to seal into the next batch's first cycle (None: nothing yet): what an
        earlier batch could not write, and what this poll found."""
        now = time.monotonic()
        if now - self._last_poll >= POLL_S and not self._out.full():
            self._last_poll = now
            for follower in self._followers:
                # Following a file another process writes may fail in any way a file can:
                # that costs the recording's seal (logged once), never the robot's batch.
                try:
                    follower.poll(self._out, now)
                except Exception as err:
                    self._report_once("recordings", f"following {follower.path} failed: {err}")
        return self._out if self._out else None

    def written(self) -> None:
        """The batch that carried ``collect``'s fields is on disk."""
        self._out = RecordingBatch()


def encode_recording_seal(cycle: int, t_ns: int, out: RecordingBatch) -> bytes:
    """The canonical bytes of a ``/trace/recording`` message (``RecordingSeal``'s field
    order, compact JSON)."""
    return orjson.dumps(
        {"cycle": cycle, "t_ns": t_ns, "windows": out.windows, "late": out.late, "gaps": out.gaps}
    )
