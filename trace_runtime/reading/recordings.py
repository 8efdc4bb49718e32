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
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.encoding.mcap_file import McapFile
from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.read_limits import DEFAULT_LIMITS, ReadLimits
from trace_runtime.records import EvidenceRef

__all__ = ["ExternalCheck", "ExternalState", "Recordings", "external_ref", "is_external"]

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


class Recordings:
    """The external MCAP recordings an investigator was given, by file name.

    Open with ``Recordings.open(paths)``: each path is an MCAP file or a directory (a rosbag2
    bag holds its ``<name>_<n>.mcap`` files and a ``metadata.yaml``); directories are searched
    for ``*.mcap`` files below them. Files are opened lazily, one index per file name.
    """

    def __init__(self, files: Mapping[str, Sequence[Path]], limits: ReadLimits = DEFAULT_LIMITS):
        self._paths = {name: tuple(paths) for name, paths in files.items()}
        self._limits = limits
        self._open: dict[Path, McapFile] = {}

    @classmethod
    def open(cls, paths: Iterable[str | Path], limits: ReadLimits = DEFAULT_LIMITS) -> Recordings:
        """Index the MCAP files at ``paths``; raise ``LogReadError`` for a path that is
        missing or a directory without MCAP files (the investigator asked for it).

        Refs name their recording by file name, so two different files of one name are
        refused (``UsageError``): checking a ref against whichever copy happens to match
        would let an altered copy pass beside an intact one."""
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
                bucket = files.setdefault(file.name, [])
                if all(file.resolve() != known.resolve() for known in bucket):
                    bucket.append(file)
        for name, bucket in files.items():
            if len(bucket) > 1:
                shown = ", ".join(str(p) for p in bucket)
                raise UsageError(
                    f"two recordings named {name} were given ({shown}): evidence refs name "
                    "their recording by file name, so give only the one the log cites"
                )
        return cls(files, limits)

    def __reduce__(self) -> tuple[Any, ...]:
        # Sent to another process (verify on an executor) as its file list, absolute so a
        # worker in another directory finds the same files; open files are not carried.
        files = {name: tuple(p.resolve() for p in paths) for name, paths in self._paths.items()}
        return (type(self), (files, self._limits))

    @property
    def names(self) -> list[str]:
        """The recording file names available, sorted."""
        return sorted(self._paths)

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
            return ExternalCheck("unresolved", name, f"recording {name} not given")
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
        return ExternalCheck("broken", name, why, absent=absent)
