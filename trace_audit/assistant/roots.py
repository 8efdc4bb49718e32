"""The folders an assistant may read: a name a model gives is a path under a configured root,
or it is refused.

A model's arguments are untrusted input (a prompt an attacker wrote may steer it), so a log
or rules file it names is looked up with the filesystem boundary every command uses
(``trace_runtime.boundary.confined``): relative, no ``..``, no component a symbolic link,
and the file itself a regular file or a folder (a FIFO would block the reader for ever).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.boundary import confined, file_kind
from trace_runtime.errors import UnsafePathError, UsageError

__all__ = ["Roots", "fingerprint"]

_FINGERPRINT_FILES = 100_000
"""Files looked at to tell whether a log changed: past this, the cache is not trusted."""


@dataclass(frozen=True, slots=True)
class Roots:
    """The configured roots, as absolute paths (the operator's choice: links in them are
    resolved once, here; nothing a model names is)."""

    paths: tuple[Path, ...]

    @classmethod
    def of(cls, paths: Sequence[str | Path]) -> Roots:
        if not paths:
            raise UsageError("give at least one --root")
        roots: list[Path] = []
        for given in map(Path, paths):
            if not given.is_dir():
                raise UsageError(f"--root {given}: not a folder")
            roots.append(given.resolve())
        return cls(tuple(roots))

    def resolve(self, name: str, what: str = "log") -> Path:
        """The path ``name`` gives under a root: absolute inside one, or relative to the
        first root that holds it ("." or "" is the first root). Anything else is an
        ``UnsafePathError`` naming the roots."""
        if "\x00" in name:
            raise self._refused(name, what)
        if name in ("", "."):
            return self.paths[0]
        for root in self.paths:
            relative = self._inside(root, name)
            if relative is None:
                continue
            if relative == "":
                return root
            path = confined(root, relative)
            if path is not None and os.path.lexists(path):
                return self._checked(path, name, what)
            if path is None and not _absent(root, relative):
                break  # it leads out of the root (a '..', a link): refused, not looked for on
            if name.startswith("/"):
                break
        raise self._refused(name, what)

    def _inside(self, root: Path, name: str) -> str | None:
        """``name`` relative to ``root``: None when it is absolute elsewhere."""
        if not name.startswith("/"):
            return name.rstrip("/")
        prefix = str(root)
        if name.rstrip("/") == prefix:
            return ""
        if name.startswith(prefix + "/"):
            return name[len(prefix) + 1 :].rstrip("/")
        return None

    def _checked(self, path: Path, name: str, what: str) -> Path:
        mode = os.lstat(path).st_mode
        if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
            return path
        raise UnsafePathError(name, f"is {file_kind(mode)}; a {what} is a file or a folder")

    def _refused(self, name: str, what: str) -> UnsafePathError:
        shown = ", ".join(str(p) for p in self.paths)
        return UnsafePathError(
            name,
            f"no such {what} under the configured roots ({shown}); a {what} is named by a "
            "path inside a root, without '..' or symbolic links",
        )


def fingerprint(path: Path) -> tuple[tuple[str, int, int], ...] | None:
    """What tells whether a log changed: each regular file under ``path`` (not through
    links) with its size and modification time; None when there are too many to look at."""
    if not path.is_dir():
        st = os.lstat(path)
        return ((path.name, st.st_size, st.st_mtime_ns),)
    found: list[tuple[str, int, int]] = []
    for folder, dirs, files in os.walk(path):  # os.walk does not descend into links
        for name in files:
            full = os.path.join(folder, name)
            st = os.lstat(full)
            if stat.S_ISREG(st.st_mode):
                found.append((os.path.relpath(full, path), st.st_size, st.st_mtime_ns))
            if len(found) > _FINGERPRINT_FILES:
                return None
        dirs.sort()
    return tuple(sorted(found))


def _absent(root: Path, relative: str) -> bool:
    """Whether ``relative`` (a name ``confined`` declined) is simply not in ``root``: a
    folder on its way missing, not a ``..`` or a link."""
    parts = relative.split("/")
    if any(part in ("", ".", "..") for part in parts) or "\\" in relative:
        return False
    path = root
    for part in parts:
        path = path / part
        try:
            mode = os.lstat(path).st_mode
        except FileNotFoundError:
            return True
        except OSError:
            return False
        if stat.S_ISLNK(mode):
            return False
    return False
