"""The witnessed state of a log's robots against the log itself (``verify --witness``).

A witness's cosignature on (origin, size N, root R) at time T says: by T, the robot had
logged at least N seals, and the first N give root R. So a log whose robot's tree now ends
before N has lost its newest cycles (``truncated_tail``: the newest segments deleted, the
newest cut short, the root rolled back to an older copy), and one whose first N seals give
another root was rewritten (``fork``). A clean comparison bounds time from outside the
robot: cycles up to the one of seal N were logged no later than T.

Where the witnessed state comes from (``source``):

- ``http(s)://...``: a witness's ``GET /checkpoint/<origin>`` (our extension), per robot;
- ``local``: the root's own store of cosigned checkpoints (``<root>/witness/*.jsonl``);
- a file path: a file holding cosigned checkpoint note(s), one after another.

With the robot's key (``--key``) each witnessed note must carry the robot's signature under
its origin; with the witness's verifier key (``--witness-key``) its cosignature must verify:
a witnessed note that fails either is a ``bad_signature`` finding and vouches for nothing.

The robots compared are the log's, and the ones ``expected`` names (``verify --expect``): a
robot the witness cosigned a tree of and the log holds no segment of has lost every cycle
(its segments deleted), a ``truncated_tail``; without ``expected`` it is never asked about.
Its notes are checked with the witness's key only (the robot's own key may be another).
"""

from __future__ import annotations

import urllib.error
import urllib.parse
import urllib.request
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from trace_runtime.boundary import read_side_file
from trace_runtime.clock import iso_utc
from trace_runtime.errors import ChainTreeError, LogReadError, NoteError
from trace_runtime.gaps import CycleRange
from trace_runtime.logger.config import default_origin
from trace_runtime.reading.chain_tree import SealLeaf, robot_seal_leaves
from trace_runtime.reading.logset import Log
from trace_runtime.tlog.cosignature_store import read_cosigned
from trace_runtime.tlog.keys import PublicKey
from trace_runtime.tlog.merkle import CompactRange
from trace_runtime.tlog.signed_note import (
    MAX_NOTE_BYTES,
    NoteVerifier,
    open_note,
    parse_checkpoint,
)
from trace_runtime.verification import Finding, FindingKind

__all__ = [
    "WitnessBound",
    "WitnessReport",
    "Witnessed",
    "compare_witnessed",
    "read_witnessed",
    "robot_origin",
]

_DASH = "\u2014 "


@dataclass(frozen=True, slots=True)
class Witnessed:
    """One cosigned checkpoint: what the witness saw and when (its cosignature's time)."""

    origin: str
    tree_size: int
    root: bytes
    witness: str
    timestamp: int
    note: str
    source: str


@dataclass(frozen=True, slots=True)
class WitnessBound:
    """An external time bound: cycles up to ``cycle`` were logged no later than ``time``."""

    robot_id: str
    witness: str
    tree_size: int
    cycle: int
    t_ns: int
    timestamp: int
    time: str
    cosignature_checked: bool


@dataclass(slots=True)
class WitnessReport:
    """What ``verify --witness`` adds: its findings, the time bounds, and what it read."""

    source: str
    findings: list[Finding] = field(default_factory=list)
    bounds: list[WitnessBound] = field(default_factory=list)
    witnessed: int = 0
    unmatched: list[str] = field(default_factory=list)
    """Robots (or origins) with no witnessed checkpoint to compare, and why."""
    witness_key: str | None = None


def _cosignatures(note: str) -> list[tuple[str, int]]:
    """(key name, stated time) of every cosignature-shaped line of a note (unverified)."""
    import base64
    import binascii

    found = []
    block = note[note.rfind("\n\n") + 2 :] if "\n\n" in note else ""
    for line in block.splitlines():
        if not line.startswith(_DASH):
            continue
        name, _, b64 = line[len(_DASH) :].partition(" ")
        try:
            raw = base64.b64decode(b64, validate=True)
        except (binascii.Error, ValueError):
            continue
        if len(raw) == 4 + 8 + 64:
            found.append((name, int.from_bytes(raw[4:12], "big")))
    return found


def _parse_witnessed(note: str, source: str) -> Witnessed:
    split = note.rfind("\n\n")
    if split < 0:
        raise NoteError("not a signed note")
    body = parse_checkpoint(note[: split + 1])
    cosigs = _cosignatures(note)
    if not cosigs:
        raise NoteError("no cosignature on the checkpoint")
    name, stamp = cosigs[-1]
    return Witnessed(body.origin, body.size, body.root, name, stamp, note, source)


def _split_notes(text: str) -> list[str]:
    """Notes one after another in a file: each ends where a signature block is followed by
    a line that is not a signature."""
    notes: list[str] = []
    current: list[str] = []
    in_block = False
    for line in text.splitlines(keepends=True):
        if in_block and not line.startswith(_DASH):
            notes.append("".join(current))
            current, in_block = [], False
            if line == "\n":
                continue
        current.append(line)
        if line == "\n" and current[:-1]:
            in_block = True
    if current:
        notes.append("".join(current))
    return [n for n in notes if n.strip()]


def _fetch(url: str, origin: str, timeout_s: float) -> str | None:
    address = url.rstrip("/") + "/checkpoint/" + urllib.parse.quote(origin, safe="/")
    try:
        with urllib.request.urlopen(address, timeout=timeout_s) as response:
            data = response.read(MAX_NOTE_BYTES + 1)
    except urllib.error.HTTPError as err:
        err.close()
        if err.code == 404:
            return None
        raise LogReadError(url, f"the witness answered HTTP {err.code} for {origin}") from err
    except (urllib.error.URLError, OSError, ValueError) as err:
        reason = getattr(err, "reason", err)
        raise LogReadError(url, f"the witness cannot be reached ({reason})") from err
    if len(data) > MAX_NOTE_BYTES:
        raise LogReadError(url, f"the witness's answer is over {MAX_NOTE_BYTES} bytes")
    return str(data.decode("utf-8", "replace"))


def robot_origin(log: Log, robot: str) -> str:
    """The origin a robot's 1.2 checkpoints name (``trace.local/<robot>`` when none does)."""
    from trace_audit.witness.push import robot_checkpoints

    checkpoints = robot_checkpoints(log, robot)
    origin = checkpoints[-1].origin if checkpoints else None
    return origin or default_origin(robot)


def expected_origin(name: str) -> tuple[str, str]:
    """(robot, origin) of an ``--expect`` value: a robot id (origin ``trace.local/<id>``, the
    logger's default) or an origin, whose last path element is the robot id."""
    if "/" in name:
        return name.rsplit("/", 1)[1], name
    return name, default_origin(name)


def read_witnessed(
    log: Log, source: str, *, timeout_s: float = 5.0, absent: Sequence[tuple[str, str]] = ()
) -> tuple[dict[str, list[Witnessed]], list[str]]:
    """The witnessed checkpoints for each robot of ``log`` and each (robot, origin) of
    ``absent`` from ``source`` (see the module doc), and the unreadable entries (one line
    each). A witness that cannot be reached, or a file that cannot be read, is a
    ``LogReadError`` (exit 3)."""
    origins = {robot_origin(log, robot): robot for robot in log.robots}
    origins |= {origin: robot for robot, origin in absent}
    found: dict[str, list[Witnessed]] = {robot: [] for robot in origins.values()}
    problems: list[str] = []
    notes: list[tuple[str, str]] = []
    if source.startswith(("http://", "https://")):
        for origin in origins:
            note = _fetch(source, origin, timeout_s)
            if note is not None:
                notes.append((note, f"{source} GET /checkpoint/{origin}"))
    elif source == "local":
        for robot in found:
            for record in read_cosigned(log.root, robot):
                notes.append((record.note, f"{log.root}/witness/{robot}.jsonl"))
    else:
        data = read_side_file(Path(source), limit=16 << 20)
        if data is None:
            raise LogReadError(source, "no such witness file")
        notes += [(n, source) for n in _split_notes(data.decode("utf-8", "replace"))]
    for note, where in notes:
        try:
            witnessed = _parse_witnessed(note, where)
        except NoteError as err:
            problems.append(f"{where}: not a cosigned checkpoint ({err})")
            continue
        owner = origins.get(witnessed.origin)
        if owner is None:
            problems.append(f"{where}: origin {witnessed.origin} names no robot of this log")
            continue
        found[owner].append(witnessed)
    return found, problems


def _finding(kind: FindingKind, robot: str, message: str, leaf: SealLeaf | None = None) -> Finding:
    where = CycleRange(leaf.cycle, leaf.cycle, leaf.t_ns, leaf.t_ns) if leaf else CycleRange()
    return Finding(kind=kind, message=message, robot_id=robot, where=where)


def _check_signatures(
    w: Witnessed, keys: Sequence[PublicKey], witness_key: NoteVerifier | None
) -> tuple[str | None, int | None]:
    """(problem, verified cosignature time). ``keys``: the robot's key and those its chain
    announced (profile 1.5); the note must be signed by one of them."""
    robot = [NoteVerifier.of(w.origin, k.raw) for k in keys]
    verifiers = [*robot, *([witness_key] if witness_key is not None else [])]
    if not verifiers:
        return None, None
    try:
        opened = open_note(w.note, verifiers)
    except NoteError as err:
        return f"does not verify: {err}", None
    if robot and all(opened.verified_by(v) is None for v in robot):
        return "carries no signature by the robot's key", None
    if witness_key is not None and opened.verified_by(witness_key) is None:
        return f"carries no signature by witness key {witness_key.name}", None
    if witness_key is not None:
        sig = opened.verified_by(witness_key)
        return None, sig.timestamp if sig else None
    return None, None


def compare_witnessed(
    log: Log,
    source: str,
    *,
    key: PublicKey | None = None,
    witness_key: NoteVerifier | None = None,
    timeout_s: float = 5.0,
    expected: Sequence[str] = (),
    announced: Mapping[str, Sequence[PublicKey]] | None = None,
) -> WitnessReport:
    """Compare each robot's log, and each ``expected`` robot the log lacks, with what the
    witness saw (see the module doc). ``announced``: by robot, the keys its chain rotated to
    from ``key`` (``RobotSummary.announced_keys``); its notes may be signed by any of them."""
    report = WitnessReport(source, witness_key=witness_key.vkey if witness_key else None)
    absent = [expected_origin(name) for name in expected]
    absent = [(robot, origin) for robot, origin in absent if robot not in log.robots]
    found, problems = read_witnessed(log, source, timeout_s=timeout_s, absent=absent)
    report.unmatched += problems
    for robot, origin in absent:
        _vanished(robot, origin, found.get(robot, []), witness_key, report)
    for robot in log.robots:
        entries = found.get(robot, [])
        if not entries:
            report.unmatched.append(f"{robot}: no witnessed checkpoint")
            continue
        trusted: list[tuple[Witnessed, int]] = []
        for w in entries:
            keys = [] if key is None else [key, *(announced or {}).get(robot, ())]
            problem, stamp = _check_signatures(w, keys, witness_key)
            if problem is not None:
                report.findings.append(
                    _finding(
                        "bad_signature",
                        robot,
                        f"the witnessed checkpoint of size {w.tree_size} from {w.source} "
                        f"{problem}; it vouches for nothing",
                    )
                )
                continue
            trusted.append((w, stamp if stamp is not None else w.timestamp))
        report.witnessed += len(trusted)
        if trusted:
            _compare_robot(log, robot, trusted, report, checked=witness_key is not None)
    return report


def _vanished(
    robot: str,
    origin: str,
    entries: list[Witnessed],
    witness_key: NoteVerifier | None,
    report: WitnessReport,
) -> None:
    """An expected robot the log holds no segment of: any tree a witness cosigned of it
    was removed whole."""
    trusted: list[tuple[Witnessed, int]] = []
    for w in entries:
        problem, stamp = _check_signatures(w, (), witness_key)
        if problem is None:
            trusted.append((w, stamp if stamp is not None else w.timestamp))
        else:
            report.unmatched.append(f"{robot}: a witnessed checkpoint {problem}; not used")
    report.witnessed += len(trusted)
    grown = [(w, stamp) for w, stamp in trusted if w.tree_size > 0]
    if not grown:
        report.unmatched.append(f"{robot}: not in this log, and no witnessed tree of {origin}")
        return
    w, stamp = max(grown, key=lambda e: (e[0].tree_size, -e[1]))
    report.findings.append(
        _finding(
            "truncated_tail",
            robot,
            f"witness {w.witness} cosigned a tree of {w.tree_size} seals of {origin} at "
            f"{iso_utc(stamp * 1_000_000_000)}, but this log holds no segment of robot "
            f"{robot}: all {w.tree_size} cycle(s) were removed",
        )
    )


def _compare_robot(
    log: Log,
    robot: str,
    entries: list[tuple[Witnessed, int]],
    report: WitnessReport,
    *,
    checked: bool,
) -> None:
    """One robot's tree against its trusted witnessed checkpoints: a tree witnessed larger
    than the log's is a ``truncated_tail``, one whose root differs a ``fork``; the largest
    that agrees bounds the time of its last cycle."""
    try:
        leaves = robot_seal_leaves(log, robot)
    except ChainTreeError as err:
        report.unmatched.append(f"{robot}: its tree cannot be read here ({err.reason})")
        return
    entries = sorted(entries, key=lambda e: (e[0].tree_size, e[1]))
    truncated = _truncated_tail(robot, entries, leaves)
    if truncated is not None:
        report.findings.append(truncated)
    best = _largest_agreeing(robot, entries, leaves, report.findings)
    if best is not None and best[0].tree_size:
        w, stamp = best
        leaf = leaves[w.tree_size - 1]
        report.bounds.append(
            WitnessBound(
                robot,
                w.witness,
                w.tree_size,
                leaf.cycle,
                leaf.t_ns,
                stamp,
                iso_utc(stamp * 1_000_000_000),
                checked,
            )
        )


def _truncated_tail(
    robot: str, entries: list[tuple[Witnessed, int]], leaves: Sequence[SealLeaf]
) -> Finding | None:
    """A ``truncated_tail`` when a witness cosigned a larger tree than the log holds, named
    by the largest (the most that was removed); ``entries`` sorted by tree size."""
    n = len(leaves)
    beyond = [(w, stamp) for w, stamp in entries if w.tree_size > n]
    if not beyond:
        return None
    w, stamp = beyond[-1]
    others = f" ({len(beyond) - 1} other witnessed tree(s) also beyond it)" if beyond[1:] else ""
    return _finding(
        "truncated_tail",
        robot,
        f"witness {w.witness} cosigned a tree of {w.tree_size} seals at "
        f"{iso_utc(stamp * 1_000_000_000)}, but this log holds {n}: the newest "
        f"{w.tree_size - n} cycle(s) were removed{others}",
        leaves[-1] if leaves else None,
    )


def _largest_agreeing(
    robot: str,
    entries: list[tuple[Witnessed, int]],
    leaves: Sequence[SealLeaf],
    findings: list[Finding],
) -> tuple[Witnessed, int] | None:
    """The largest witnessed tree the log's first seals give the same root for, at the
    earliest time it was vouched for; each that differs is a ``fork`` in ``findings``.
    ``entries`` sorted by tree size, then time: the log's tree is grown once."""
    tree = CompactRange()
    at = 0
    best: tuple[Witnessed, int] | None = None
    for w, stamp in entries:
        if w.tree_size > len(leaves):
            continue
        while at < w.tree_size:
            tree.append(leaves[at].leaf)
            at += 1
        if tree.root() != w.root:
            findings.append(
                _finding(
                    "fork",
                    robot,
                    f"witness {w.witness} cosigned another tree of size {w.tree_size} at "
                    f"{iso_utc(stamp * 1_000_000_000)}: the log's first {w.tree_size} seals "
                    "were rewritten",
                    leaves[w.tree_size - 1] if w.tree_size else None,
                )
            )
            continue
        if best is None or w.tree_size > best[0].tree_size:
            best = (w, stamp)
    return best
