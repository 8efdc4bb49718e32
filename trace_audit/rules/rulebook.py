"""A rules file: named STL requirements in TOML, read and checked before any log is.

The shape (docs/rules.md), kept so that rules travel between tools and people::

    [[rule]]
    name = "stop_near_person"
    stl = "always((nearest.person < 2.0) implies eventually[0:0.5](channel.speed.actual <= 0.05))"
    description = "optional: what the rule asks, for people"

Every rule's formula is parsed by rtamt when the file is read, so a bad formula is one
``RulesError`` line naming the file and the rule (exit 2), before a log is opened.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from trace_audit.rules.formula import Formula, RulesError, compile_formula

__all__ = ["Rule", "parse_rules", "read_rules"]

_MAX_FILE_BYTES = 1 << 20
_FIELDS = frozenset(("name", "stl", "description"))


@dataclass(frozen=True, slots=True)
class Rule:
    """One named requirement: its formula as written, and as checked."""

    name: str
    stl: str
    description: str
    formula: Formula


def read_rules(path: str | Path) -> tuple[Rule, ...]:
    """The rules of the TOML file at ``path``; ``RulesError`` for a file that cannot be read
    or a rule that cannot be used."""
    try:
        with Path(path).open("rb") as f:
            data = f.read(_MAX_FILE_BYTES + 1)
    except OSError as err:
        raise RulesError(f"{path}: cannot read the rules file ({err.strerror or err})") from err
    if len(data) > _MAX_FILE_BYTES:
        raise RulesError(f"{path}: a rules file is at most {_MAX_FILE_BYTES} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise RulesError(f"{path}: not UTF-8 text ({err.reason})") from err
    return parse_rules(text, str(path))


def parse_rules(text: str, origin: str = "<rules>") -> tuple[Rule, ...]:
    """The rules of a TOML text (``origin`` names it in errors)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise RulesError(f"{origin}: not valid TOML: {err}") from err
    raw = data.get("rule")
    if not isinstance(raw, list) or not raw:
        raise RulesError(f"{origin}: no rules: write each as a [[rule]] table with name and stl")
    rules: list[Rule] = []
    seen: set[str] = set()
    for i, entry in enumerate(raw, 1):
        rule = _rule(entry, i, origin)
        if rule.name in seen:
            raise RulesError(f"{origin}: rule {rule.name!r} is defined twice")
        seen.add(rule.name)
        rules.append(rule)
    return tuple(rules)


def _rule(entry: object, i: int, origin: str) -> Rule:
    if not isinstance(entry, dict):
        raise RulesError(f"{origin}: rule #{i} is not a table")
    name = entry.get("name")
    if name is not None and not isinstance(name, str):
        raise RulesError(f'{origin}: rule #{i}: name must be text (name = "...")')
    if not name or not name.strip():
        raise RulesError(f'{origin}: rule #{i} has no name (name = "...")')
    stl = entry.get("stl")
    if stl is not None and not isinstance(stl, str):
        raise RulesError(f'{origin}: rule {name!r}: stl must be text (stl = "always(...)")')
    if not stl or not stl.strip():
        raise RulesError(f'{origin}: rule {name!r} has no formula (stl = "...")')
    unknown = sorted(set(entry) - _FIELDS)
    if unknown:
        raise RulesError(f"{origin}: rule {name!r} has an unknown field {unknown[0]!r}")
    description = entry.get("description", "")
    if not isinstance(description, str):
        raise RulesError(f"{origin}: rule {name!r}: description is text")
    try:
        formula = compile_formula(name, stl, origin=origin)
    except RulesError as err:
        raise RulesError(f"{origin}: {err}") from err
    return Rule(name, stl, description, formula)
