"""The one error root of the project and the whole tree of its errors.

Every error raised on purpose is a ``TraceError``; third-party errors are wrapped where they
arise (``raise ... from err``). The three branches under the root say who must act, and the
CLI's exit code follows from the branch alone (``trace_audit.cli.app.exit_code_for``)::

    TraceError
    ├── UsageError                 exit 2: asked wrongly (an option, an order, a time)
    │   └── TimeOutOfRangeError        a time outside the log's range
    ├── InputError                 exit 3: what was handed in cannot be read as asked
    │   ├── RecordError                a record that is not of its schema (a robot's, a file's)
    │   ├── LogReadError               a log (file, root) that cannot be read (path, reason)
    │   │   ├── NotTraceLogError           valid MCAP, not the TRACE profile
    │   │   ├── LogLimitError              over a read limit (a bomb, a flood)
    │   │   ├── PayloadError               a message that is not its channel's JSON
    │   │   ├── UnsafePathError            a link, FIFO or escaping name in a folder
    │   │   ├── StaleCatalogError          a catalog row that is not its segment
    │   │   ├── ChainTreeError             a robot's tree that this log cannot give
    │   │   └── NotHotSegmentError         a finished warm or cold file asked to be followed
    │   ├── ShapeError                 a value or shape the cold codec cannot take
    │   ├── ColdFormatError            a malformed cold block
    │   ├── MerkleError                a tree state or proof that cannot be
    │   ├── NoteError                  a signed note, checkpoint, key or signature off its spec
    │   │   └── UnverifiedNoteError        a note no known key signed
    │   ├── WitnessProtocolError       a witness request or answer off the protocol
    │   ├── WitnessStoreError          a cosigned checkpoint that cannot be stored as given
    │   ├── WireProtocolError          a recorder frame or message off its wire protocol
    │   ├── LogLockedError             a log another live logger writes
    │   └── VerificationError          a copy that is not what its source becomes
    └── StorageError               exit 4: the filesystem refused a write
        └── SegmentWriteError          a batch the segment writer could not write

The investigator adds usage errors of its own beside the questions that raise them (a
window outside the log, several robots where one is asked for, a rules file). Anything
else, a ``TraceError`` outside these branches or any other exception, is a bug: it
surfaces (in tests, as a traceback), never as "unreadable input".
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from trace_runtime.clock import is_wall_clock, iso_utc, offset_hint

if TYPE_CHECKING:
    from trace_runtime.tlog.signed_note import NoteSignature

__all__ = [
    "EXIT_CANNOT_WRITE",
    "EXIT_FINDINGS",
    "EXIT_NOT_INSTALLED",
    "EXIT_OK",
    "EXIT_UNREADABLE",
    "EXIT_USAGE",
    "ChainTreeError",
    "ColdFormatError",
    "InputError",
    "LogLimitError",
    "LogLockedError",
    "LogReadError",
    "MerkleError",
    "NotHotSegmentError",
    "NotTraceLogError",
    "NoteError",
    "PayloadError",
    "RecordError",
    "SegmentWriteError",
    "ShapeError",
    "StaleCatalogError",
    "StorageError",
    "TimeOutOfRangeError",
    "TraceError",
    "UnsafePathError",
    "UnverifiedNoteError",
    "UsageError",
    "VerificationError",
    "WireProtocolError",
    "WitnessProtocolError",
    "WitnessStoreError",
]


class TraceError(Exception):
    """Base of every error this project raises on purpose."""

    def __reduce__(self) -> tuple[object, ...]:
        # A fleet index task fails in another process (a local pool, a Dask worker) and its
        # error crosses back pickled; the subclasses' own ``__init__`` signatures differ
        # from ``args``, so the error is rebuilt from its message and fields instead.
        return (_rebuilt, (type(self), self.args, dict(self.__dict__)))


def _rebuilt(
    kind: type[TraceError], args: tuple[object, ...], fields: dict[str, object]
) -> TraceError:
    """A ``TraceError`` of ``kind`` with ``args`` and ``fields``, not calling its ``__init__``."""
    err = kind.__new__(kind)
    Exception.__init__(err, *args)
    err.__dict__.update(fields)
    return err


# -- exit 2: asked wrongly ----------------------------------------------------------------


class UsageError(TraceError):
    """The logger, a reader or a command was used wrongly (a layer added twice in one
    cycle, an option that cannot be, a question the log cannot be asked)."""


class TimeOutOfRangeError(UsageError):
    """A time asked about lies outside the log's time range (shown in ISO UTC when
    ``clock`` names a wall clock)."""

    def __init__(self, t_ns: int, start_ns: int, end_ns: int, clock: str = "") -> None:
        def shown(ns: int) -> str:
            wall = is_wall_clock(clock, start_ns)
            return iso_utc(ns, digits=3) if wall else f"{ns / 1e9:.3f} s"

        super().__init__(
            f"t={shown(t_ns)} is outside the log's range [{shown(start_ns)}, {shown(end_ns)}]"
            + offset_hint(clock, start_ns, t_ns)
        )
        self.t_ns = t_ns
        self.start_ns = start_ns
        self.end_ns = end_ns


# -- exit 3: what was handed in cannot be read as asked ------------------------------------


class InputError(TraceError):
    """What was handed in (a file, a folder, a record, a note, a proof, a witness's answer)
    cannot be read as asked: damaged, foreign, over a limit, or not of its specification."""


class RecordError(InputError, ValueError):
    """A record is not of its schema: handed to the logger, a programming error in the
    robot (raised at the call site); read from a file, a damaged record."""


class LogReadError(InputError):
    """A log cannot be read: missing, not MCAP, truncated beyond recovery, or not TRACE."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"{path}: {reason}")
        self.path = path
        self.reason = reason


class NotTraceLogError(LogReadError):
    """The file is valid MCAP but not of the TRACE profile (e.g. a rosbag2 recording)."""


class LogLimitError(LogReadError):
    """A file asks the reader for more than its limits allow (a decompression bomb, a
    flood of records): refused, in bounded time and memory."""


class PayloadError(LogReadError):
    """A stored message's data is not what its channel promises: not JSON, nested deeper
    than the parser allows, or not of its record's schema. ``path`` names the segment."""

    def __init__(self, path: str, topic: str, reason: str) -> None:
        super().__init__(path, f"{topic} message: {reason}")
        self.topic = topic


class UnsafePathError(LogReadError):
    """A name in an untrusted folder that the tools refuse to follow: a symbolic link, a
    FIFO, socket, device or directory where a file is expected, or a name leading outside."""


class StaleCatalogError(LogReadError):
    """A lazily opened log found a segment that is not what the root's catalog row says (a
    catalog edited, or copied with other files): the row is ignored, and a query is asked
    again of the log opened in full."""


class ChainTreeError(LogReadError):
    """A robot's tree cannot be read from this log: its chain does not start at its genesis
    here (an excerpt, or earlier segments removed), or a segment of it is missing."""


class NotHotSegmentError(LogReadError):
    """The file is a warm or cold segment: written whole and finished, read by ``Segment``."""


class ShapeError(InputError, ValueError):
    """A value cannot be given a shape (a bare scalar, too deep, too big) or a shape is bad."""


class ColdFormatError(InputError, ValueError):
    """A cold block is malformed (wrapped into ``LogReadError`` by callers). A ``TraceError``
    so that one that escapes still maps to an exit code; a ``ValueError`` because it is one."""


class MerkleError(InputError, ValueError):
    """A Merkle tree was asked for something it does not have (a saved state that cannot be
    a compact range, a leaf index beyond the tree)."""


class NoteError(InputError, ValueError):
    """A signed note, checkpoint, key or signature that does not follow its specification,
    or whose signature by a known key does not verify."""


class UnverifiedNoteError(NoteError):
    """A well-formed note that no known key signed (the spec says: reject it)."""

    def __init__(self, message: str, unverified: tuple[NoteSignature, ...]) -> None:
        super().__init__(message)
        self.unverified = unverified


class WitnessProtocolError(InputError, ValueError):
    """An add-checkpoint request (or a witness's answer) that is not what the protocol says."""


class WitnessStoreError(InputError, ValueError):
    """A cosigned checkpoint that cannot be stored as given (not a checkpoint note, no
    cosignature line, a robot id that is not a file name)."""


class WireProtocolError(InputError, ValueError):
    """A frame or message a recorder client sent that is not what the wire protocol says
    (PROFILE section 13): over the frame limit, not a JSON object, an unknown kind, a field
    missing or of the wrong type. The recorder refuses it with this reason."""


class LogLockedError(InputError):
    """Another live logger already writes this robot's log here (one writer per robot and root).

    ``pid`` is the holder's process id when it could be read from the lock file, else None.
    """

    def __init__(self, path: str, pid: int | None) -> None:
        holder = f"pid {pid}" if pid is not None else "another process"
        super().__init__(f"{path}: the log is being written by {holder} (lock held)")
        self.path = path
        self.pid = pid


class VerificationError(InputError):
    """A copy of a segment is not what its source becomes (compaction checks every copy it
    makes, and every copy a killed run left, before anything is removed)."""


# -- exit 4: the filesystem refused a write -----------------------------------------------


class StorageError(TraceError):
    """The filesystem refused a write a command must make (read-only folder, full disk,
    permission): nothing was lost, and nothing half-written was left in place."""

    def __init__(self, path: str, reason: str) -> None:
        super().__init__(f"{path}: cannot write: {reason}")
        self.path = path
        self.reason = reason


class SegmentWriteError(StorageError):
    """A batch could not be written. ``rolled_back`` says whether the segment is still usable.

    ``kept``: the write failed and could not be rolled back, yet the batch's chunk is in the
    file whole (its ``written`` bytes), so a reader recovers every cycle of it; the segment
    is given up all the same. The message is the reason alone: the writer's callers name
    the segment (``path`` is empty).
    """

    def __init__(
        self, reason: str, *, rolled_back: bool, kept: bool = False, written: int = 0
    ) -> None:
        TraceError.__init__(self, reason)
        self.path = ""
        self.reason = reason
        self.rolled_back = rolled_back
        self.kept = kept
        self.written = written


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
EXIT_NOT_INSTALLED = 5
"""A command whose extra is not installed (a robot's install: ``trace_audit.entry``)."""
