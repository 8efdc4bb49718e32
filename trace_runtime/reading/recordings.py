"""External recordings: MCAP files beside a TRACE log whose messages evidence refs name.

A ROS 2 robot already records its sensors with rosbag2 into MCAP. Its TRACE log need not copy
them: an evidence ref with ``recording`` set names a message in such a file by file name,
topic, log time, sequence and the SHA-256 of the message's stored data (PROFILE.md section
11). This module finds that message and checks its digest. It reads the recording through the
bounded byte layer (``mcap_file.McapFile``) and never decodes a message: checking a digest
needs only the stored bytes, so the runtime stays free of the ROS 2 libraries (decoding for
display lives in ``trace_audit.evidence``).

Three outcomes, kept apart because they mean different things to an investigator:

- ``resolved``: the recording is here and holds the message the ref names (digest equal when
  the ref carries one);
- ``broken``: the recording is here but the message is not, or its data differs from the
  digest: the recording was altered, or the ref was wrong when it was written;
- ``unresolved``: the recording the ref names was not given, so nothing was checked.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import EvidenceRef

__all__ = [
    "NEAR_NS",
    "ExternalCheck",
    "ExternalState",
    "Recordings",
    "declare_recordings",
    "external_ref",
    "is_external",
    "recording_files",
    "recording_name",
]

NEAR_NS = 1_000_000_000
"""How far from a ref's time a message with the ref's digest is looked for (PROFILE §11)."""

_SPLIT_INDEX = re.compile(r"_(\d+)$")
"""rosbag2 numbers a bag's split files ``<bag>_<n>.mcap``."""

ExternalState = Literal["resolved", "broken", "unresolved"]


@dataclass(frozen=True, slots=True)
class ExternalCheck:
    """What became of one external evidence ref: its state, why, and the message found."""

    state: ExternalState
    recording: str
    detail: str = ""
    message: RawMessage | None = None
    path: Path | None = None
    """The file the message was found in (None unless resolved)."""
    absent: bool = False
    """Broken because the recording holds no message of that topic and time at all (cut
    short, or the message removed), not because a message differs."""
    shift_ns: int = 0
    """Resolved by its digest near the ref's time: how far the recorded message's log time
    is from the ref's (a robot that cited a message's stamp, not its receive time)."""


def external_ref(
    recording: str | Path, topic: str, log_time_ns: int, data: bytes, sequence: int | None = None
) -> EvidenceRef:
    """The evidence ref of a message another writer (e.g. rosbag2) recorded into an MCAP file.

    ``recording``: that file's path or name (only the name is kept); ``data``: the message's
    stored bytes exactly as that writer wrote them (CDR for ROS 2), whose SHA-256 the ref
    carries so a verifier can tell a changed recording from the one the robot cited.
    """
    return EvidenceRef(
        topic=topic,
        log_time_ns=log_time_ns,
        sequence=sequence,
        digest=hashlib.sha256(data).hexdigest(),
        recording=Path(recording).name,
    )


def is_external(ref: Mapping[str, Any]) -> bool:
    """True when an evidence ref (as JSON) names a message in another recording."""
    return isinstance(ref.get("recording"), str)


def recording_name(path: str | Path) -> str:
    """What refs call a recording: its folder's name (a rosbag2 bag, split files and all) or
    its file's name (one MCAP file)."""
    return Path(path).name


def recording_files(path: Path) -> list[Path]:
    """The MCAP files of a recording as they are now: the file itself, or a bag folder's
    ``*.mcap`` files in split order (``<bag>_2.mcap`` before ``<bag>_10.mcap``); [] when
    there is nothing (yet)."""
    if path.is_file():
        return [path]
    if not path.is_dir():
        return []
    return sorted((p for p in path.glob("*.mcap") if p.is_file()), key=_split_order)


def _split_order(path: Path) -> tuple[int, str]:
    match = _SPLIT_INDEX.search(path.stem)
    return (int(match.group(1)) if match else -1, path.name)


def declare_recordings(paths: Iterable[str | Path], base: Path) -> tuple[tuple[str, str], ...]:
    """The ``trace.session`` ``recordings`` of a robot that cites ``paths``: each by its name,
    at its path relative to ``base`` (the log root, or a single-file log's folder) when it
    lies below or beside it, so that a root moved with its recordings still finds them;
    absolute otherwise. Raises ``UsageError`` for two recordings of one name (refs could not
    tell them apart) or a path with no name."""
    declared: dict[str, str] = {}
    for raw in paths:
        path = Path(raw).absolute()
        name = recording_name(path)
        if name in ("", ".", ".."):
            raise UsageError(f"recording {raw!s} has no name refs could cite")
        if name in declared:
            raise UsageError(
                f"two recordings named {name}: refs name their recording, so names must differ"
            )
        relative = os.path.relpath(path, base.absolute())
        declared[name] = (
            Path(relative).as_posix() if not relative.startswith("../../") else (path.as_posix())
        )
    return tuple(declared.items())


class Recordings:
    """The external MCAP recordings evidence refs can be resolved against, by name.

    A recording is a rosbag2 folder (its ``*.mcap`` split files) or one MCAP file; a ref
    names it by the folder's or the file's name (``recording_name``), and refs written
    before recordings were named so (profile 1.1-1.3) by the file's name, which is kept too.
    ``Recordings.open(paths)`` takes what an investigator gives; ``Recordings.declared``
    adds what the log's segments declare (profile 1.4). Files are opened lazily.
    """

    def __init__(
        self,
        files: Mapping[str, Sequence[Path]],
        limits: ReadLimits = DEFAULT_LIMITS,
        missing: Mapping[str, Path] | None = None,
    ):
        self._paths = {name: tuple(paths) for name, paths in files.items()}
        self._limits = limits
        self._open: dict[Path, McapFile] = {}
        self.missing: dict[str, Path] = dict(missing or {})
        """Recordings the log declares that are not where it says (moved, never made): refs
        into them are unresolved, so what they would show is unknown."""

    @classmethod
    def open(cls, paths: Iterable[str | Path], limits: ReadLimits = DEFAULT_LIMITS) -> Recordings:
        """Index the MCAP files at ``paths``; raise ``LogReadError`` for a path that is
        missing or a directory without MCAP files (the investigator asked for it).

        Each file is known by its own name and by its folder's (a bag's files by the bag's
        name); a directory is searched below for them. Two different files or folders of one
        name are refused (``UsageError``): checking a ref against whichever copy happens to
        match would let an altered copy pass beside an intact one."""
        files: dict[str, list[Path]] = {}
        for raw in paths:
            path = Path(raw)
            if path.is_dir():
                found = sorted(p for p in path.rglob("*.mcap") if p.is_file())
                if not found:
                    raise LogReadError(str(path), "no .mcap recording in this directory")
            elif path.is_file():
                found = [path]
            else:
                raise LogReadError(str(path), "no such recording")
            for file in found:
                _add(files, file.name, [file])
                if file.parent != path.parent or path.is_dir():
                    _add(files, file.parent.name, recording_files(file.parent))
        return cls(files, limits)

    @classmethod
    def declared(
        cls,
        sessions: Iterable[tuple[Path, Sequence[tuple[str, str]]]],
        given: Recordings | None = None,
        limits: ReadLimits = DEFAULT_LIMITS,
    ) -> Recordings:
        """The recordings a log declares, ``sessions`` being each segment's (folder its paths
        are relative to, ``trace.session`` ``recordings``), joined with those ``given``
        (which win: ``--evidence`` is the override for a moved copy). A declared recording
        that is not there is listed in ``missing``."""
        files: dict[str, list[Path]] = (
            {} if given is None else {name: list(paths) for name, paths in given._paths.items()}
        )
        missing: dict[str, Path] = {}
        for base, declared in sessions:
            for name, where in declared:
                if name in files:
                    continue
                path = base / where
                found = recording_files(path)
                if found:
                    files[name] = found
                    missing.pop(name, None)
                    for file in found:
                        files.setdefault(file.name, [file])
                else:
                    missing.setdefault(name, path)
        return cls(files, limits, missing)

    def __reduce__(self) -> tuple[Any, ...]:
        # Sent to another process (verify on an executor) as its file list, absolute so a
        # worker in another directory finds the same files; open files are not carried.
        files = {name: tuple(p.resolve() for p in paths) for name, paths in self._paths.items()}
        return (type(self), (files, self._limits, self.missing))

    @property
    def names(self) -> list[str]:
        """The recording names (folders and files) available, sorted."""
        return sorted(self._paths)

    def files_of(self, name: str) -> tuple[Path, ...]:
        """The files of the recording ``name`` (a bag's split files in order); () if unknown."""
        return self._paths.get(name, ())

    def __bool__(self) -> bool:
        return bool(self._paths)

    def _file(self, path: Path) -> McapFile:
        found = self._open.get(path)
        if found is None:
            found = self._open[path] = McapFile(path, self._limits)
        return found

    def check(self, ref: Mapping[str, Any]) -> ExternalCheck:
        """Find the message an external ref names and compare its digest.

        Raises ``LogReadError`` when a recording of that name cannot be read at all (not
        MCAP, truncated before its header): that is the investigator's input, not a finding.
        """
        name = ref.get("recording")
        topic, t_ns = ref.get("topic"), ref.get("log_time_ns")
        if not isinstance(name, str):
            raise ValueError("not an external evidence ref (no recording)")
        if type(topic) is not str or type(t_ns) is not int:
            return ExternalCheck("broken", name, "malformed ref (topic or log_time_ns missing)")
        paths = self._paths.get(name)
        if not paths:
            where = self.missing.get(name)
            why = (
                f"recording {name} not found at {where}" if where else f"recording {name} not given"
            )
            return ExternalCheck("unresolved", name, why)
        sequence, want = ref.get("sequence"), ref.get("digest")
        why, absent = f"no {topic} message at log_time_ns={t_ns} in {name}", True
        for path in paths:
            for msg in self._file(path).iter_messages(t_ns, t_ns):
                if msg.topic != topic or msg.log_time_ns != t_ns:
                    continue
                absent = False
                if sequence is not None and msg.sequence != sequence:
                    why = f"sequence {sequence} does not match the recorded {msg.sequence}"
                    continue
                if want is not None and hashlib.sha256(msg.data).hexdigest() != want:
                    why = f"{topic} message data in {name} does not match the ref's digest"
                    continue
                return ExternalCheck("resolved", name, "", msg, path)
        if absent and isinstance(want, str):
            near = self._near(name, paths, topic, t_ns, want)
            if near is not None:
                return near
        return ExternalCheck("broken", name, why, absent=absent)

    def _near(
        self, name: str, paths: Sequence[Path], topic: str, t_ns: int, want: str
    ) -> ExternalCheck | None:
        """The message of ``topic`` whose data has digest ``want`` within ``NEAR_NS`` of
        ``t_ns``: a robot may know a message's header stamp, not the time its recorder
        received it (the log time), and the digest says which message it is."""
        for path in paths:
            for msg in self._file(path).iter_messages(max(0, t_ns - NEAR_NS), t_ns + NEAR_NS):
                if msg.topic == topic and hashlib.sha256(msg.data).hexdigest() == want:
                    shift = msg.log_time_ns - t_ns
                    return ExternalCheck("resolved", name, "", msg, path, shift_ns=shift)
        return None


def _add(files: dict[str, list[Path]], name: str, found: Sequence[Path]) -> None:
    """Know ``found`` by ``name``; a different set already known by it is refused."""
    bucket = files.setdefault(name, [])
    if not bucket:
        bucket.extend(found)
        return
    known = {p.resolve() for p in bucket}
    if {p.resolve() for p in found} <= known or known <= {p.resolve() for p in found}:
        if len(found) > len(bucket):
            bucket[:] = found
        return
    shown = ", ".join(str(p) for p in [*bucket, *found])
    raise UsageError(
        f"two recordings named {name} were given ({shown}): evidence refs name their "
        "recording, so give only the one the log cites"
    )
