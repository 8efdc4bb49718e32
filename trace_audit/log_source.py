"""What the investigator's functions accept as a log, and the check that it holds decisions.

Every reader (``explain``, ``timeline``, ``why``, ``info``, ``export``, the report) takes a
path (file, directory or log root) or an already open ``Log`` and opens it the same way.
"""

from __future__ import annotations

from pathlib import Path

from trace_runtime.errors import LogReadError
from trace_runtime.reading.logset import Log, open_log

__all__ = ["LogSource", "as_log", "require_cycles"]

LogSource = Log | str | Path
"""A log as the investigator's functions take it: a path, or a ``Log`` already open."""


def as_log(source: LogSource, *, lazy: bool = False) -> Log:
    """An open ``Log`` for a path (file, directory or log root) or an already open one.

    ``lazy``: the caller asks about one moment, so a catalogued root's segments are opened
    only when a query reaches them (``open_log``)."""
    return source if isinstance(source, Log) else open_log(source, lazy=lazy)


def require_cycles(log: Log) -> None:
    """Raise ``LogReadError`` when the log holds no decision cycle at all (an empty log)."""
    if log.holds_cycle_messages():
        return
    if next(log.iter_cycles(), None) is None:
        recovered = " (recovered from an unfinished segment)" if log.recovered else ""
        raise LogReadError(str(log.root), f"the log holds no decision cycles{recovered}")
