"""A compliance profile: a TOML file that maps each clause of a law (its reference and a
one-line summary) to the checks ``comply`` runs over a log root.

The shape (docs/compliance.md)::

    name = "my-profile"
    title = "What law this is"
    [[clause]]
    reference = "Art. 12(1)"
    summary = "one line, in your own words"
    checks = ["chain", "gaps", "signed"]
    keep_days = 184        # with the "retention" check: how long records are kept
    full_detail = true     # optional: warm summaries count as deleting detail

Profiles shipped with the package are found by name (``SHIPPED``); any other argument is a
path to a user's own file. A profile that cannot be used is a ``ProfileError`` (exit 2)
naming the file and the clause, before any log is read.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Literal, get_args

from trace_runtime.errors import UsageError

__all__ = [
    "SHIPPED",
    "CheckName",
    "Clause",
    "Profile",
    "ProfileError",
    "load_profile",
    "shipped_path",
]

CheckName = Literal["versions", "signed", "witnessed", "gaps", "chain", "retention", "safety_rules"]
CHECK_NAMES: tuple[CheckName, ...] = get_args(CheckName)
SHIPPED = ("machinery-2023-1230", "ai-act-art12")
"""The profiles shipped in ``trace_audit/comply/profiles/``, by name."""

_MAX_FILE_BYTES = 256 << 10
_TOP = frozenset(("name", "title", "applies_from", "source", "clause"))
_CLAUSE = frozenset(("reference", "summary", "checks", "keep_days", "full_detail"))


class ProfileError(UsageError):
    """A profile that cannot be used as given (exit 2): the file and what is wrong."""


@dataclass(frozen=True, slots=True)
class Clause:
    """One clause: where it is in the law, what it asks (our words), and its checks."""

    reference: str
    summary: str
    checks: tuple[CheckName, ...]
    keep_days: int | None = None
    full_detail: bool = False


@dataclass(frozen=True, slots=True)
class Profile:
    """A profile as read: its name, the law's title, and its clauses in order."""

    name: str
    title: str
    clauses: tuple[Clause, ...]
    path: str
    """Where it was read from (shown on the evidence page, so a reader can open it)."""
    applies_from: str | None = None
    source: str | None = None

    @property
    def keep_days(self) -> int | None:
        """The longest period any clause keeps records for (None: the profile sets none)."""
        return max((c.keep_days for c in self.clauses if c.keep_days), default=None)

    @property
    def full_detail(self) -> bool:
        return any(c.full_detail for c in self.clauses)


def shipped_path(name: str) -> Path:
    """The file of the shipped profile ``name`` (inside the installed package)."""
    folder = resources.files("trace_audit.comply") / "profiles"
    return Path(str(folder / f"{name}.toml"))


def load_profile(name_or_path: str) -> Profile:
    """A shipped profile by name, or a user's own profile file by path."""
    path = shipped_path(name_or_path) if name_or_path in SHIPPED else Path(name_or_path)
    try:
        with path.open("rb") as f:
            data = f.read(_MAX_FILE_BYTES + 1)
    except OSError as err:
        known = ", ".join(SHIPPED)
        raise ProfileError(
            f"{name_or_path}: no such profile ({err.strerror or err}); shipped: {known}"
        ) from err
    if len(data) > _MAX_FILE_BYTES:
        raise ProfileError(f"{path}: a profile is at most {_MAX_FILE_BYTES} bytes")
    try:
        table = tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ProfileError(f"{path}: not a TOML text ({err})") from err
    return _profile(table, str(path))


def _profile(table: dict[str, object], origin: str) -> Profile:
    unknown = sorted(set(table) - _TOP)
    if unknown:
        raise ProfileError(
            f"{origin}: unknown key {unknown[0]!r} (known: {', '.join(sorted(_TOP))})"
        )
    name, title = table.get("name"), table.get("title", "")
    if not isinstance(name, str) or not name.strip():
        raise ProfileError(f'{origin}: the profile needs a name (name = "...")')
    if not isinstance(title, str):
        raise ProfileError(f"{origin}: title must be text")
    raw = table.get("clause")
    if not isinstance(raw, list) or not raw:
        raise ProfileError(f"{origin}: no clauses: write each as a [[clause]] table")
    clauses = tuple(_clause(entry, i, origin) for i, entry in enumerate(raw, 1))
    applies, source = table.get("applies_from"), table.get("source")
    return Profile(
        name=name.strip(),
        title=title,
        clauses=clauses,
        path=origin,
        applies_from=applies if isinstance(applies, str) else None,
        source=source if isinstance(source, str) else None,
    )


def _clause(entry: object, i: int, origin: str) -> Clause:
    """One ``[[clause]]`` table, every field checked (a bool is not a number of days)."""
    if not isinstance(entry, dict):
        raise ProfileError(f"{origin}: clause #{i} is not a table")
    where = f"{origin}: clause #{i}"
    unknown = sorted(set(entry) - _CLAUSE)
    if unknown:
        raise ProfileError(f"{where}: unknown key {unknown[0]!r}")
    reference, summary = entry.get("reference"), entry.get("summary")
    if not isinstance(reference, str) or not reference.strip():
        raise ProfileError(f"{where}: needs a reference (where in the law)")
    where = f"{origin}: clause {reference}"
    if not isinstance(summary, str) or not summary.strip():
        raise ProfileError(f"{where}: needs a one-line summary")
    checks = entry.get("checks")
    if not isinstance(checks, list) or not checks:
        raise ProfileError(f"{where}: needs checks, some of {', '.join(CHECK_NAMES)}")
    bad = [c for c in checks if c not in CHECK_NAMES]
    if bad:
        raise ProfileError(f"{where}: unknown check {bad[0]!r} (known: {', '.join(CHECK_NAMES)})")
    days, full = entry.get("keep_days"), entry.get("full_detail", False)
    if days is not None and (isinstance(days, bool) or not isinstance(days, int) or days <= 0):
        raise ProfileError(f"{where}: keep_days must be a positive number of days")
    if "retention" in checks and days is None:
        raise ProfileError(f"{where}: the retention check needs keep_days")
    if not isinstance(full, bool):
        raise ProfileError(f"{where}: full_detail must be true or false")
    return Clause(reference.strip(), summary.strip(), tuple(checks), days, full)
