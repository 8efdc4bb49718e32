"""How much one SQL session over the index may take: memory, threads, wall-clock time, and
the size of the result it hands back.

A statement is the user's (``query``) or carries their condition (``find --where``), and
the index folder may be someone else's: either can ask DuckDB for far more than the machine
has (``range(1e12)``, ``repeat('x', 2e9)``, a 300 MB string in a Parquet row). Three bounds:

- DuckDB's own ``memory_limit`` and ``threads``, set before the session is locked;
- a watchdog that interrupts the statement after ``timeout_s``;
- for the CLI, whose process is its own, a cap on the process's data segment
  (``RLIMIT_DATA``): DuckDB's buffer manager does not count every allocation (a long string,
  a large list), but every allocation counts against the cap, and DuckDB turns a refused
  one into an out-of-memory error instead of taking the machine's memory.

Going over any bound is a ``UsageError`` (exit 2) that names the option that raises it.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

from trace_runtime.errors import UsageError

if TYPE_CHECKING:
    import duckdb

__all__ = [
    "QueryLimits",
    "cap_process_memory",
    "format_size",
    "over_limit",
    "parse_size",
    "row_bytes",
    "watchdog",
]

_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12}
_UNITS |= {"KIB": 2**10, "MIB": 2**20, "GIB": 2**30, "TIB": 2**40}


@dataclass(frozen=True, slots=True)
class QueryLimits:
    """The bounds of one session; the defaults are the CLI's."""

    memory_bytes: int = 10**9
    """DuckDB's ``memory_limit``; the CLI caps its process's data at twice this beyond
    what it already holds (results and strings live outside DuckDB's count)."""
    timeout_s: float = 30.0
    """Wall-clock time per statement before it is interrupted."""
    threads: int = min(4, os.cpu_count() or 1)
    """DuckDB's worker threads."""
    result_bytes: int = 256 * 10**6
    """The most a result may hold once fetched (its values' sizes, summed)."""

    def __post_init__(self) -> None:
        if self.memory_bytes < 16 * 2**20:
            raise UsageError(f"--memory-limit must be at least 16 MiB, got {self.memory_bytes}")
        if not self.timeout_s > 0:
            raise UsageError(f"--timeout must be more than 0 s, got {self.timeout_s}")
        if self.threads < 1:
            raise UsageError(f"threads must be at least 1, got {self.threads}")

    def apply(self, con: duckdb.DuckDBPyConnection) -> None:
        """Set DuckDB's own bounds on a session that is not yet locked."""
        con.execute(f"SET memory_limit = '{int(self.memory_bytes)}B'")
        con.execute(f"SET threads = {int(self.threads)}")


def parse_size(text: str) -> int:
    """``1GB``, ``512MiB``, ``2e9`` -> bytes; ``UsageError`` naming the forms allowed."""
    found = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]*)?(?:[eE][0-9]+)?)\s*([A-Za-z]*)\s*", text)
    unit = found.group(2).upper() if found else ""
    if found is None or unit not in _UNITS:
        raise UsageError(f"--memory-limit must be a size such as 1GB or 512MiB, got {text!r}")
    return int(float(found.group(1)) * _UNITS[unit])


def format_size(n: int) -> str:
    """Bytes as the shortest of GB / MB / kB text (decimal units, as DuckDB prints)."""
    for unit, size in (("GB", 10**9), ("MB", 10**6), ("kB", 10**3)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} B"


def over_limit(err: BaseException, limits: QueryLimits) -> UsageError | None:
    """The one-line refusal for a statement stopped by a bound, or None for any other error."""
    import duckdb

    if isinstance(err, duckdb.InterruptException):
        return UsageError(
            f"SQL: stopped after {limits.timeout_s:g} s (--timeout; raise it to wait longer)"
        )
    if isinstance(err, duckdb.OutOfMemoryException | MemoryError):
        return UsageError(
            f"SQL: needs more than --memory-limit {format_size(limits.memory_bytes)} "
            "(raise it, or narrow the statement)"
        )
    return None


@contextlib.contextmanager
def watchdog(con: duckdb.DuckDBPyConnection, limits: QueryLimits) -> Iterator[None]:
    """Interrupt whatever ``con`` runs once ``limits.timeout_s`` have passed."""
    timer = threading.Timer(limits.timeout_s, con.interrupt)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


def row_bytes(row: tuple[object, ...]) -> int:
    """What a fetched row holds, near enough to bound a result: the length of each text and
    binary value, 8 bytes for any other scalar, nested values summed."""
    total = 0
    stack: list[object] = list(row)
    while stack:
        value = stack.pop()
        if isinstance(value, str | bytes | bytearray):
            total += len(value)
        elif isinstance(value, list | tuple):
            stack.extend(value)
        elif isinstance(value, dict):
            stack.extend(value.keys())
            stack.extend(value.values())
        else:
            total += 8
    return total


def cap_process_memory(limits: QueryLimits) -> None:
    """Cap this process's data segment at what it holds now plus twice the memory limit.

    For a process that runs one query and exits (the CLI), never for a library caller's:
    the cap is the process's, and only lowered (a cap already lower stays)."""
    try:
        import resource
    except ImportError:  # not POSIX: DuckDB's own memory_limit is the bound
        return
    held = _data_bytes()
    if held is None:
        return
    cap = held + 2 * limits.memory_bytes
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    if soft != resource.RLIM_INFINITY and soft <= cap:
        return
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_DATA, (cap, hard))


def _data_bytes() -> int | None:
    """The process's data segment now (``VmData``), or None where Linux does not say."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmData:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError):
        return None
    return None
