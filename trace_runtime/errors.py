"""The one error root of the project and its few meaningful subclasses."""

from __future__ import annotations

from trace_runtime.clock import is_wall_clock, iso_utc


class TraceError(Exception):
    """Base of every error this project raises on purpose."""


class RecordError(TraceError, ValueError):
    """A record handed to the logger is invalid: a programming error in the robot."""


class UsageError(TraceError):
    """The logger or a reader was used out of order (e.g. a layer added twice in one cycle)."""


class LogReadError(TraceError):
    """A log cannot be read: missing, not MCAP, truncated beyond recovery, or not TRACE."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"{path}: {reason}")
        self.path = path
        self.reason = reason


class NotTraceLogError(LogReadError):
    """The file is valid MCAP but not of the TRACE profile (e.g. a rosbag2 recording)."""


class TimeOutOfRangeError(TraceError):
    """A time asked about lies outside the log's time range (shown in ISO UTC when
    ``clock`` names a wall clock)."""

    def __init__(self, t_ns: int, start_ns: int, end_ns: int, clock: str = "") -> None:
        def shown(ns: int) -> str:
            wall = is_wall_clock(clock, start_ns)
            return iso_utc(ns, digits=3) if wall else f"{ns / 1e9:.3f} s"

        super().__init__(
            f"t={shown(t_ns)} is outside the log's range [{shown(start_ns)}, {shown(end_ns)}]"
        )
        self.t_ns = t_ns
        self.start_ns = start_ns
        self.end_ns = end_ns


class LogLimitError(LogReadError):
    """A file asks the reader for more than its limits allow (a decompression bomb, a
    flood of records): refused, in bounded time and memory."""


class LogLockedError(TraceError):
    """Another live logger already writes this robot's log here (one writer per robot and root).

    ``pid`` is the holder's process id when it could be read from the lock file, else None.
    """

    def __init__(self, path: str, pid: int | None) -> None:
        holder = f"pid {pid}" if pid is not None else "another process"
        super().__init__(f"{path}: the log is being written by {holder} (lock held)")
        self.path = path
        self.pid = pid


class VerificationError(TraceError):
    """A copy of a segment is not what its source becomes (compaction checks every copy it
    makes, and every copy a killed run left, before anything is removed)."""


class PayloadError(LogReadError):
    """A stored message's data is not what its channel promises: not JSON, nested deeper
    than the parser allows, or not of its record's schema. ``path`` names the segment."""

    def __init__(self, path: str, topic: str, reason: str) -> None:
        super().__init__(path, f"{topic} message: {reason}")
        self.topic = topic


class UnsafePathError(LogReadError):
    """A name in an untrusted folder that the tools refuse to follow: a symbolic link, a
    FIFO, socket, device or directory where a file is expected, or a name leading outside."""


class StorageError(TraceError):
    """The filesystem refused a write a command must make (read-only folder, full disk,
    permission): nothing was lost, and nothing half-written was left in place."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"{path}: cannot write: {reason}")
        self.path = path
        self.reason = reason


# The exit codes every program of the project documents (trace-audit, trace-sim): their numbers
# live beside the errors they stand for, so a program that may not import the investigator
# (sim/cli.py) still says what trace-audit says. Which error gets which code is each CLI's one
# mapping (trace_audit.cli.app.exit_code_for).
EXIT_OK = 0
EXIT_FINDINGS = 1
"""Findings: verify failed, a metric under its threshold, a counterfactual that does not hold."""
EXIT_USAGE = 2
"""A bad option or value, a time outside the log."""
EXIT_UNREADABLE = 3
"""Input that cannot be read: missing, not MCAP, truncated, not a TRACE log."""
EXIT_CANNOT_WRITE = 4
"""Output that cannot be written: a read-only folder, a full disk, a name already taken."""
