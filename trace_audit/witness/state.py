"""A witness's memory: per origin, the latest checkpoint it cosigned, in SQLite.

One row an origin (size, root, the cosigned note, the time of its cosignature), written in
one transaction with ``synchronous=FULL`` (the commit is on disk before the witness answers
200), so a restarted witness never cosigns a tree inconsistent with one it cosigned before.
"""

from __future__ import annotations

import contextlib
import sqlite3
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.errors import StorageError

__all__ = ["STATE_FILE", "Latest", "WitnessState"]

STATE_FILE = "witness.sqlite"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS latest (
    origin TEXT PRIMARY KEY,
    tree_size INTEGER NOT NULL,
    root BLOB NOT NULL,
    note TEXT NOT NULL,
    timestamp INTEGER NOT NULL
)
"""


@dataclass(frozen=True, slots=True)
class Latest:
    """The latest checkpoint cosigned for an origin: its note carries the cosignature."""

    origin: str
    tree_size: int
    root: bytes
    note: str
    timestamp: int


class WitnessState:
    """The state folder's database; safe to share between the server's threads."""

    def __init__(self, folder: str | Path) -> None:
        folder = Path(folder)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(
                folder / STATE_FILE, check_same_thread=False, isolation_level=None
            )
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute(_SCHEMA)
        except (OSError, sqlite3.Error) as err:
            raise StorageError(str(folder), f"cannot open the witness state ({err})") from err
        self._lock = threading.Lock()

    @contextlib.contextmanager
    def locked(self) -> Iterator[WitnessState]:
        """Hold the state while a request is checked against it and its answer stored."""
        with self._lock:
            yield self

    def latest(self, origin: str) -> Latest | None:
        row = self._db.execute(
            "SELECT origin, tree_size, root, note, timestamp FROM latest WHERE origin = ?",
            (origin,),
        ).fetchone()
        return None if row is None else Latest(row[0], row[1], bytes(row[2]), row[3], row[4])

    def store(self, latest: Latest) -> None:
        """Replace the origin's row, durably (one transaction, fsynced on commit)."""
        try:
            self._db.execute("BEGIN IMMEDIATE")
            self._db.execute(
                "INSERT OR REPLACE INTO latest (origin, tree_size, root, note, timestamp) "
                "VALUES (?, ?, ?, ?, ?)",
                (latest.origin, latest.tree_size, latest.root, latest.note, latest.timestamp),
            )
            self._db.execute("COMMIT")
        except sqlite3.Error as err:
            with contextlib.suppress(sqlite3.Error):
                self._db.execute("ROLLBACK")
            raise StorageError("witness state", f"cannot store a checkpoint ({err})") from err

    def close(self) -> None:
        self._db.close()
