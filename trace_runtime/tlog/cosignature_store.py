"""The store of cosigned checkpoints beside a log: ``<root>/witness/<robot_id>.jsonl``.

One JSON object a line, appended and fsynced, never rewritten or deleted:

    {"robot_id": "amr-7", "origin": "trace.local/amr-7", "tree_size": 1200,
     "root": "<64 hex>", "note": "<the checkpoint note with the robot's signature and the
     witness's cosignature line(s)>", "witness": "<the witness's key name>",
     "timestamp": <the cosignature's time, POSIX seconds>, "witness_url": "<where from>"}

What a line states is what its note says; nothing here is trusted: ``verify --witness``
opens the note (with the robot's key and, given one, the witness's) before it believes it.
Reading is bounded and hostile-file safe (the folder and the file are never followed
through a link, a FIFO is refused, not waited on), and a torn last line (a writer killed
mid-append) is skipped, as is any line that is not a record of this shape.
"""

from __future__ import annotations

import base64
import binascii
import os
import re
import stat
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import orjson

from trace_runtime.boundary import append_line, fsync_dir, read_side_file
from trace_runtime.errors import (
    NoteError,
    StorageError,
    UnsafePathError,
    WitnessStoreError,
)
from trace_runtime.tlog.signed_note import parse_checkpoint

__all__ = [
    "MAX_STORE_BYTES",
    "WITNESS_FOLDER",
    "Cosigned",
    "append_cosigned",
    "cosigned_note",
    "read_cosigned",
    "store_path",
]

WITNESS_FOLDER = "witness"
MAX_STORE_BYTES = 64 << 20
"""A robot's store is read up to this size (a checkpoint a minute for years is ~1 GB; the
store is read from its end: the newest lines are the ones kept when it is larger)."""
_ROBOT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
_DASH = "\u2014 "


@dataclass(frozen=True, slots=True)
class Cosigned:
    """One stored cosigned checkpoint (see the module doc for the fields)."""

    robot_id: str
    origin: str
    tree_size: int
    root: str
    note: str
    witness: str
    timestamp: int
    witness_url: str = ""


def store_path(root: str | Path, robot_id: str) -> Path:
    """Where ``robot_id``'s cosigned checkpoints live under log root ``root``."""
    if not isinstance(robot_id, str) or not _ROBOT_ID.match(robot_id):
        raise WitnessStoreError(f"robot id {robot_id!r} is not a file name")
    return Path(root) / WITNESS_FOLDER / f"{robot_id}.jsonl"


def _signature_name_and_time(line: str) -> tuple[str, int]:
    """The key name and the stated time of a cosignature line (not verified here)."""
    if not line.startswith(_DASH) or "\n" in line.rstrip("\n"):
        raise WitnessStoreError("a cosignature is one signature line")
    name, _, b64 = line[len(_DASH) :].rstrip("\n").partition(" ")
    try:
        raw = base64.b64decode(b64, validate=True)
    except (binascii.Error, ValueError) as err:
        raise WitnessStoreError("a cosignature line's signature is not base64") from err
    if not name or len(raw) != 4 + 8 + 64:
        raise WitnessStoreError("not a tlog-cosignature/v1 line (key id, time, signature)")
    return name, int.from_bytes(raw[4:12], "big")


def cosigned_note(note: str, cosignatures: Sequence[str]) -> str:
    """The robot's signed checkpoint note with the witness's cosignature lines added."""
    if not note.endswith("\n") or "\n\n" not in note:
        raise WitnessStoreError("not a signed note")
    extra = "".join(c if c.endswith("\n") else c + "\n" for c in cosignatures)
    return note + extra


def append_cosigned(
    root: str | Path,
    robot_id: str,
    note: str,
    cosignatures: Sequence[str],
    *,
    witness_url: str = "",
) -> Cosigned:
    """Store a checkpoint ``note`` (as the robot signed it) and the cosignature line(s) a
    witness returned for it; appended and fsynced, the folder created when absent.

    Origin, size and root are read from the note; the witness's key name and time from its
    first cosignature line. Raises ``WitnessStoreError`` for what is not a cosigned
    checkpoint and ``StorageError``/``UnsafePathError`` for a store that cannot be written.
    """
    path = store_path(root, robot_id)
    if not cosignatures:
        raise WitnessStoreError("no cosignature to store")
    text, sep, _ = note.partition("\n\n")
    try:
        checkpoint = parse_checkpoint(text + "\n") if sep else None
    except NoteError as err:
        raise WitnessStoreError(f"not a checkpoint note: {err}") from err
    if checkpoint is None:
        raise WitnessStoreError("not a signed note")
    witness, timestamp = _signature_name_and_time(cosignatures[0])
    record = Cosigned(
        robot_id,
        checkpoint.origin,
        checkpoint.size,
        checkpoint.root.hex(),
        cosigned_note(note, cosignatures),
        witness,
        timestamp,
        witness_url,
    )
    _make_folder(Path(root))
    append_line(path, orjson.dumps(asdict(record)) + b"\n")
    return record


def _make_folder(root: Path) -> None:
    """The root's witness folder, created when absent; checked as ``_folder_of`` checks
    it, whether it was there, made here, or made by another writer meanwhile."""
    if _folder_of(root) is not None:
        return
    folder = root / WITNESS_FOLDER
    try:
        folder.mkdir(mode=0o755)
    except FileExistsError:
        pass
    except OSError as err:
        raise StorageError(str(folder), f"cannot create it ({err.strerror or err})") from err
    fsync_dir(root)
    if _folder_of(root) is None:  # gone again between the two looks
        raise StorageError(str(folder), "cannot create it (removed as it was made)")


def _folder_of(root: Path) -> Path | None:
    folder = root / WITNESS_FOLDER
    try:
        mode = os.lstat(folder).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return None  # no store, or ``root`` is a segment file: nothing beside it is its own
    except OSError as err:
        raise UnsafePathError(str(folder), f"cannot look at it ({err.strerror or err})") from err
    if not stat.S_ISDIR(mode):
        raise UnsafePathError(str(folder), "the witness store is not a folder (a link is refused)")
    return folder


def _record(value: object) -> Cosigned | None:
    if not isinstance(value, dict):
        return None
    try:
        record = Cosigned(
            robot_id=value["robot_id"],
            origin=value["origin"],
            tree_size=value["tree_size"],
            root=value["root"],
            note=value["note"],
            witness=value["witness"],
            timestamp=value["timestamp"],
            witness_url=value.get("witness_url", ""),
        )
    except (KeyError, TypeError):
        return None
    strings = (record.robot_id, record.origin, record.root, record.note, record.witness)
    if not all(isinstance(s, str) for s in (*strings, record.witness_url)):
        return None
    numbers = (record.tree_size, record.timestamp)
    if any(isinstance(n, bool) or not isinstance(n, int) or n < 0 for n in numbers):
        return None
    return record


def read_cosigned(
    root: str | Path, robot_id: str, *, limit: int = MAX_STORE_BYTES
) -> list[Cosigned]:
    """``robot_id``'s stored cosigned checkpoints in the order they were stored ([] when
    there is none). A torn last line and lines not of the record's shape are skipped; a
    link, a FIFO or a folder where the store belongs is an ``UnsafePathError``; a store
    over ``limit`` bytes a ``LogLimitError``."""
    path = store_path(root, robot_id)
    if _folder_of(Path(root)) is None:
        return []
    data = read_side_file(path, limit=limit)
    if not data:
        return []
    lines = data.split(b"\n")
    if lines[-1]:  # no newline after it: a torn append
        lines = lines[:-1]
    found: list[Cosigned] = []
    for line in lines:
        if not line:
            continue
        try:
            value = orjson.loads(line)
        except orjson.JSONDecodeError:
            continue
        record = _record(value)
        if record is not None and record.robot_id == robot_id:
            found.append(record)
    return found
