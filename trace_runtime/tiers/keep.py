"""What a log root must keep by law: the compliance profiles it carries (``compliance.toml``)
and the guard that stops compaction and retention from deleting records younger than them.

A root adopts a profile (``trace-audit comply ROOT --profile NAME --adopt``), which writes one
``[[profile]]`` table into ``ROOT/compliance.toml``: its name, the days its records are kept
(``keep_days``) and whether they must stay in full detail (``full_detail``: the warm tier's
summaries then count as deleting what they drop). The period is copied into the root, not
looked up again by name, so a root says by itself what it keeps. Compaction resolves its
defaults through ``resolve_periods``: a request that would delete (or, with ``full_detail``,
summarise) records younger than the longest period is refused, one line, exit 2, unless the
caller overrides it by name. A file that cannot be read is refused too (exit 3): an unreadable
promise to keep records never lets them go.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.boundary import read_side_file, write_atomic
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.tiers.durations import DAY_NS

__all__ = [
    "COMPLIANCE_NAME",
    "KeptProfile",
    "RootKeep",
    "adopt_profile",
    "read_keep",
    "resolve_periods",
]

COMPLIANCE_NAME = "compliance.toml"
OVERRIDE_FLAG = "--override-compliance"
"""The CLI's name of the override, named in every refusal so the user knows the way out."""

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")
_HEADER = (
    "# The compliance profiles this log root serves (written by trace-audit comply --adopt).\n"
    "# compact and retention keep every record younger than the longest keep_days below (in\n"
    "# full, no warm summaries, when full_detail) unless run with --override-compliance.\n"
)


@dataclass(frozen=True, slots=True)
class KeptProfile:
    """One adopted profile: its name, how long the root keeps records for it, and whether in
    full detail."""

    name: str
    keep_days: int
    full_detail: bool

    @property
    def keep_ns(self) -> int:
        return self.keep_days * DAY_NS


@dataclass(frozen=True, slots=True)
class RootKeep:
    """The profiles a root carries; the strictest one decides."""

    profiles: tuple[KeptProfile, ...]

    @property
    def keep_ns(self) -> int:
        return max((p.keep_ns for p in self.profiles), default=0)

    @property
    def full_detail_ns(self) -> int:
        """How long records must stay in full (0: summaries are allowed at once)."""
        return max((p.keep_ns for p in self.profiles if p.full_detail), default=0)

    def named(self, period_ns: int) -> str:
        """The profiles that ask for at least ``period_ns``, for an error message."""
        return ", ".join(p.name for p in self.profiles if p.keep_ns >= period_ns)


def read_keep(root: Path) -> RootKeep | None:
    """The profiles ``root`` carries, or None when it carries none (no ``compliance.toml``)."""
    path = root / COMPLIANCE_NAME
    data = read_side_file(path, limit=64 << 10)
    if data is None:
        return None
    try:
        table = tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise LogReadError(str(path), f"not TOML ({err})") from err
    rows = table.get("profile", [])
    if not isinstance(rows, list):
        raise LogReadError(str(path), "[[profile]] must be an array of tables")
    return RootKeep(tuple(_kept(path, row) for row in rows))


def _kept(path: Path, row: object) -> KeptProfile:
    """One ``[[profile]]`` table, each field checked (a bool is not a number of days)."""
    if not isinstance(row, dict):
        raise LogReadError(str(path), "a [[profile]] entry is not a table")
    name, days, full = row.get("name"), row.get("keep_days"), row.get("full_detail", False)
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise LogReadError(str(path), f"profile name {name!r} is not a plain name")
    if isinstance(days, bool) or not isinstance(days, int) or not 0 < days <= 36_500:
        raise LogReadError(str(path), f"profile {name}: keep_days must be 1..36500 days")
    if not isinstance(full, bool):
        raise LogReadError(str(path), f"profile {name}: full_detail must be true or false")
    return KeptProfile(name, days, full)


def adopt_profile(root: Path, profile: KeptProfile) -> RootKeep:
    """Write ``profile`` into ``root``'s ``compliance.toml`` (replacing one of its name),
    atomically; the profiles the root then carries."""
    if not _NAME.fullmatch(profile.name):
        raise UsageError(f"profile name {profile.name!r} is not a plain name")
    if not root.is_dir():
        raise UsageError(f"{root}: not a log root (no such folder)")
    before = read_keep(root)
    others = [p for p in (before.profiles if before else ()) if p.name != profile.name]
    keep = RootKeep((*others, profile))
    text = _HEADER + "".join(
        f'\n[[profile]]\nname = "{p.name}"\nkeep_days = {p.keep_days}\n'
        f"full_detail = {'true' if p.full_detail else 'false'}\n"
        for p in keep.profiles
    )
    write_atomic(root / COMPLIANCE_NAME, text.encode())
    return keep


def resolve_periods(
    root: Path,
    keep: RootKeep | None,
    *,
    tier: str,
    older_than_ns: int | None,
    default_older_than_ns: int,
    retention_ns: int | None,
    retention_default: bool,
    override: bool,
) -> tuple[int, int | None]:
    """(older_than_ns, retention_ns) a compaction of ``root`` runs with, the root's compliance
    profiles considered: a default is raised to their period, an explicit request below it
    is refused (``UsageError``) unless ``override``."""
    full_ns = keep.full_detail_ns if keep and tier == "warm" else 0
    keep_ns = keep.keep_ns if keep else 0
    if older_than_ns is None:
        older_than_ns = max(default_older_than_ns, full_ns)
    elif older_than_ns < full_ns and not override:
        raise UsageError(_refusal(root, keep, full_ns, f"--older-than {_days(older_than_ns)}",
                                  "summarise (lossy warm tier)"))  # fmt: skip
    if retention_default and retention_ns is not None:
        retention_ns = max(retention_ns, keep_ns)
    elif retention_ns is not None and retention_ns < keep_ns and not override:
        raise UsageError(_refusal(root, keep, keep_ns, f"--retention {_days(retention_ns)}",
                                  "delete"))  # fmt: skip
    return older_than_ns, retention_ns


def _refusal(root: Path, keep: RootKeep | None, period_ns: int, asked: str, verb: str) -> str:
    names = keep.named(period_ns) if keep else ""
    return (
        f"{root} keeps its records {_days(period_ns)} for {names} ({COMPLIANCE_NAME}): "
        f"{asked} would {verb} younger ones; pass {OVERRIDE_FLAG} to do it anyway"
    )


def _days(ns: int) -> str:
    days, rest = divmod(ns, DAY_NS)
    return f"{days}d" if not rest else f"{ns / DAY_NS:.2f}d"
