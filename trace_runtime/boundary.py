"""The filesystem boundary of a folder the tools keep files in: a log root or an index folder.

Such folders travel (copied between machines, synced, unpacked from an archive someone sent),
so what is in them is untrusted. Every read of a side file (the catalog, the retention
journal, the index manifest), every write, rename and delete the tools make there goes
through this module, which holds four rules:

- A name taken from a file (a manifest's ``files``, a catalog's ``path``) is used only when it
  stays inside the folder it belongs to: relative, no ``..``, no component a symbolic link.
- Nothing is written or deleted through a symbolic link, and nothing but a regular file is
  read as a side file: a FIFO would block the reader for ever, a device or a directory is not
  what the name promises. Such a name is refused with one clear error (``UnsafePathError``).
- Files written aside are created exclusively under a name no one else holds, so a link
  planted at the partial name is never followed, and two runs never share one.
- A side file is read only up to a size bound and parsed only up to a JSON depth bound.

Write failures (a read-only folder, a full disk) become ``StorageError``: one line, its own
exit code, never a traceback.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, BinaryIO

import orjson

from trace_runtime.errors import (
    LogLimitError,
    LogReadError,
    StorageError,
    UnsafePathError,
    UsageError,
)

__all__ = [
    "SIDE_FILE_BYTES",
    "SIDE_FILE_DEPTH",
    "append_line",
    "confined",
    "create_aside",
    "create_exclusive",
    "file_kind",
    "folder_lock",
    "fsync_dir",
    "open_lock_file",
    "read_side_file",
    "read_side_json",
    "regular_file",
    "remove_own_file",
    "remove_stale_asides",
    "remove_stale_partials",
    "storage_error",
    "tier_folder",
    "write_atomic",
]

SIDE_FILE_BYTES = 64 << 20
"""The largest side file read (a catalog of ~100,000 segments is about 60 MB)."""
SIDE_FILE_DEPTH = 32
"""The deepest JSON a side file may nest (the catalog and the manifest nest 3 deep)."""

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_NONBLOCK = getattr(os, "O_NONBLOCK", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)


def storage_error(path: Path, err: OSError) -> StorageError:
    """The ``StorageError`` for an ``OSError`` raised while writing ``path``."""
    return StorageError(str(path), err.strerror or str(err))


def _not_a_file(path: Path) -> UnsafePathError | None:
    """The refusal for ``path`` when something other than a regular file holds the name
    (why an open of it failed), or None."""
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return None
    return None if stat.S_ISREG(mode) else _refused(path, mode)


def _refused(path: Path, mode: int) -> UnsafePathError:
    return UnsafePathError(str(path), f"is {file_kind(mode)}, not a regular file; refused")


def file_kind(mode: int) -> str:
    """What a file of ``mode`` is, in the words an error message uses."""
    for test, name in (
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISSOCK, "a socket"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
    ):
        if test(mode):
            return name
    return "a regular file" if stat.S_ISREG(mode) else "not a regular file"


def regular_file(path: Path) -> bool:
    """Whether ``path`` exists as a regular file (not through a link); False when absent.

    Raises ``UnsafePathError`` when something else holds the name."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return False
    except OSError as err:
        raise UnsafePathError(str(path), f"cannot look at it ({err.strerror or err})") from err
    if not stat.S_ISREG(mode):
        raise _refused(path, mode)
    return True


def tier_folder(root: Path, tier: str) -> Path | None:
    """``root/tier`` when it is a folder of the root, None when there is none.

    A tier folder that is a symbolic link would give two views of one root (readers that
    follow it, writers that delete through it), so it is refused alike by every command."""
    path = root / tier
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    except OSError as err:
        raise UnsafePathError(str(path), f"cannot look at it ({err.strerror or err})") from err
    if stat.S_ISLNK(mode):
        raise UnsafePathError(
            str(path), "the tier folder is a symbolic link; a log root's tiers are folders in it"
        )
    return path if stat.S_ISDIR(mode) else None


def confined(base: Path, name: str) -> Path | None:
    """``base/name`` for a name read from an untrusted file, or None when it would lead out
    of ``base``: absolute, with a ``..`` or empty component, or through a symbolic link."""
    if not name or "\\" in name or "\x00" in name or name.startswith("/"):
        return None
    parts = name.split("/")
    if any(part in ("", ".", "..") for part in parts):
        return None
    path = base
    for part in parts[:-1]:
        path = path / part
        try:
            if not stat.S_ISDIR(os.lstat(path).st_mode):
                return None
        except OSError:
            return None
    target = path / parts[-1]
    with contextlib.suppress(OSError):
        if stat.S_ISLNK(os.lstat(target).st_mode):
            return None
    return target


def read_side_file(path: Path, *, limit: int = SIDE_FILE_BYTES) -> bytes | None:
    """The bytes of side file ``path``, or None when there is none.

    Opened without following a link and without blocking (a FIFO is refused, not waited on);
    refused when it is not a regular file or holds more than ``limit`` bytes."""
    try:
        fd = os.open(path, os.O_RDONLY | _NOFOLLOW | _NONBLOCK | _CLOEXEC)
    except FileNotFoundError:
        return None
    except OSError as err:
        raise _not_a_file(path) or UnsafePathError(
            str(path), f"cannot read it ({err.strerror or err})"
        ) from err
    info = os.fstat(fd)
    if not stat.S_ISREG(info.st_mode):
        os.close(fd)
        raise _refused(path, info.st_mode)
    with os.fdopen(fd, "rb") as f:
        if info.st_size > limit:
            raise LogLimitError(str(path), f"holds {info.st_size:,} bytes, over the {limit:,} read")
        data = f.read(limit + 1)
    if len(data) > limit:
        raise LogLimitError(str(path), f"grew past the {limit:,} bytes read while being read")
    return data


def read_side_json(
    path: Path, *, limit: int = SIDE_FILE_BYTES, max_depth: int = SIDE_FILE_DEPTH
) -> Any | None:
    """The JSON value of side file ``path`` (bounded as ``read_side_file`` is, and nested at
    most ``max_depth`` deep), or None when there is none. Not JSON: ``LogReadError``."""
    data = read_side_file(path, limit=limit)
    if data is None:
        return None
    try:
        value = orjson.loads(data)
    except orjson.JSONDecodeError as err:
        raise LogReadError(str(path), f"not JSON ({err})") from err
    if _depth_over(value, max_depth):
        raise LogLimitError(str(path), f"nests deeper than {max_depth} levels")
    return value


def _depth_over(value: Any, max_depth: int) -> bool:
    """Whether ``value`` nests deeper than ``max_depth`` (walked without recursion)."""
    if not isinstance(value, dict | list):
        return False
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > max_depth:
            return True
        children = item.values() if isinstance(item, dict) else item
        stack.extend((child, depth + 1) for child in children if isinstance(child, dict | list))
    return False


def create_exclusive(path: Path) -> BinaryIO:
    """Create ``path`` for writing; fails if anything holds the name, a link included."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW | _CLOEXEC, 0o644)
    except FileExistsError:
        raise
    except OSError as err:
        raise storage_error(path, err) from err
    return os.fdopen(fd, "wb")


def _written_aside(path: Path, data: bytes) -> Path:
    """A fresh sibling of ``path`` (``create_aside``) holding ``data``, fsynced."""
    tmp, f = create_aside(path)
    try:
        with f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except OSError as err:
        _unlink_own(tmp)
        raise storage_error(path, err) from err
    return tmp


def _unlink_own(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        os.unlink(tmp)  # our own file, made just now under a name no one else holds


def write_atomic(path: Path, data: bytes) -> None:
    """Replace ``path`` with ``data``: write a fresh sibling, fsync it, rename it over, fsync
    the folder. Refused when ``path`` is held by anything but a regular file."""
    regular_file(path)
    tmp = _written_aside(path, data)
    try:
        os.replace(tmp, path)
    except OSError as err:
        _unlink_own(tmp)
        raise storage_error(path, err) from err
    remove_stale_partials(path)
    fsync_dir(path.parent)


def write_new(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path``, which must not exist: a fresh sibling is written and
    fsynced, then linked in under ``path`` (a name taken meanwhile, by anything, is never
    replaced), and the folder fsynced. ``StorageError`` when the name is held."""
    tmp = _written_aside(path, data)
    try:
        try:
            os.link(tmp, path, follow_symlinks=False)
        except FileExistsError:
            raise StorageError(str(path), "it exists, and is never overwritten") from None
        except OSError:  # a filesystem without hard links: the same refusal, then a rename
            if os.path.lexists(path):
                raise StorageError(str(path), "it exists, and is never overwritten") from None
            os.replace(tmp, path)
    except OSError as err:
        raise storage_error(path, err) from err
    finally:
        _unlink_own(tmp)
    fsync_dir(path.parent)


def remove_stale_partials(path: Path) -> None:
    """Remove the partial files of earlier ``write_atomic`` calls on ``path`` that were
    killed before their rename (``remove_stale_asides`` for that one name)."""
    remove_stale_asides(path.parent, lambda name: name == path.name)


def remove_stale_asides(folder: Path, own: Callable[[str], bool]) -> int:
    """Remove from ``folder`` the files ``create_aside`` made beside a name ``own`` accepts
    whose writer was killed before it linked them in: named as ``create_aside`` names them,
    regular files (never a link or a folder), and written by a process that no longer runs
    (a live one may be writing right now; a reused id only keeps a file). The count removed."""
    removed = 0
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            aside = _aside_of(entry.name)
            if aside is None or not own(aside[0]):
                continue
            if aside[1] == os.getpid() or _running(aside[1]):
                continue
            if entry.is_file(follow_symlinks=False):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)
                    removed += 1
    return removed


def _aside_of(name: str) -> tuple[str, int] | None:
    """The name a partial file of ``create_aside``'s stands beside and its writer's process
    id (``.NAME.PID.N.partial``), or None for any other name."""
    if not (name.startswith(".") and name.endswith(".partial")):
        return None
    parts = name[1 : -len(".partial")].rsplit(".", 2)
    if len(parts) != 3 or not parts[0] or not all(p.isascii() and p.isdigit() for p in parts[1:]):
        return None
    pid = int(parts[1])
    return (parts[0], pid) if 0 < pid < 1 << 31 else None  # os.kill takes no larger id


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # it exists, owned by someone else
    return True


def create_aside(path: Path) -> tuple[Path, BinaryIO]:
    """A new file beside ``path`` under a name no one holds (this process's id and a count),
    created exclusively: a link or file planted at a likely name is skipped, never followed."""
    for attempt in range(1000):
        tmp = path.with_name(f".{path.name}.{os.getpid()}.{attempt}.partial")
        try:
            return tmp, create_exclusive(tmp)
        except FileExistsError:
            continue
        except StorageError as err:  # the folder refuses: say so of the file asked for
            raise StorageError(str(path), err.reason) from err
    raise StorageError(str(path), "no free name for a partial file beside it")


def append_line(path: Path, line: bytes) -> None:
    """Append ``line`` to journal ``path`` and fsync it; refused through a link or into
    anything but a regular file."""
    try:
        fd = os.open(
            path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | _NOFOLLOW | _NONBLOCK | _CLOEXEC, 0o644
        )
    except OSError as err:
        raise _not_a_file(path) or storage_error(path, err) from err
    with os.fdopen(fd, "ab") as f:
        mode = os.fstat(f.fileno()).st_mode
        if not stat.S_ISREG(mode):
            raise _refused(path, mode)
        try:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        except OSError as err:
            raise storage_error(path, err) from err


def remove_own_file(path: Path) -> str | None:
    """Unlink ``path`` if it is a regular file; otherwise leave it and say why (a link or
    anything else is never removed: what it names is not the tools' own)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    except OSError as err:
        return f"cannot look at it ({err.strerror or err})"
    if not stat.S_ISREG(mode):
        return f"it is {file_kind(mode)}"
    try:
        os.unlink(path)
    except OSError as err:
        return f"cannot remove it ({err.strerror or err})"
    fsync_dir(path.parent)
    return None


def fsync_dir(directory: Path) -> None:
    """Make a rename or unlink in ``directory`` durable (no-op where unsupported)."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def open_lock_file(path: Path) -> int:
    """A descriptor of lock file ``path`` (created if absent), opened read-write without
    following a link or blocking; refused unless it is a regular file."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | _NOFOLLOW | _NONBLOCK | _CLOEXEC, 0o644)
    except OSError as err:
        raise _not_a_file(path) or storage_error(path, err) from err
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise _refused(path, mode)
    return fd


@contextlib.contextmanager
def folder_lock(path: Path, *, held: str, remove: bool = False) -> Iterator[None]:
    """Hold an exclusive ``flock`` on lock file ``path`` (released even on kill -9).

    ``held`` is the refusal's wording when another process holds it (a ``UsageError``); the
    lock file is opened without following a link, and a folder the tool cannot write is a
    ``StorageError``. ``remove``: the lock file is deleted when the block ends, while the
    lock is still held."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock; each command stays correct when run alone
        yield
        return
    fd = _locked(path, held, fcntl)
    try:
        yield
    finally:
        if remove:  # before the lock is let go: a run that starts now makes a new file
            _unlink_own(path)
        os.close(fd)


def _locked(path: Path, held: str, fcntl: Any) -> int:
    """A descriptor holding the ``flock`` of the file now at ``path``.

    A holder that removes its lock file as it ends may do so between our open and our
    lock: the lock then holds a file no longer at ``path``, which guards nothing, so the
    name is opened again."""
    while True:
        fd = open_lock_file(path)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as err:
            os.close(fd)
            raise UsageError(held) from err
        here = os.fstat(fd)
        try:
            there = os.lstat(path)
        except FileNotFoundError:
            there = None
        if there is not None and (there.st_dev, there.st_ino) == (here.st_dev, here.st_ino):
            return fd
        os.close(fd)
