"""The sensor messages a decision's evidence refs may resolve to: its own cycle's and a
bounded number of cycles before it, and the external recordings given (``--evidence``).

A ref resolves when a message in the window has its topic and log time and, when the ref
carries them, its sequence and the SHA-256 of its data; a ref into an external recording
(PROFILE.md section 11) resolves against that recording, or stays unresolved, with a reason
that says it was not checked rather than broken, when the recording was not given.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict, deque
from collections.abc import Mapping, Sequence

from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.reading.recordings import ExternalCheck, ExternalState, Recordings

__all__ = ["DEFAULT_SENSOR_WINDOW", "SensorWindow", "check_in_recordings"]

DEFAULT_SENSOR_WINDOW = 50
"""Cycles before a decision whose sensor messages its refs may resolve to (5 s at 10 Hz)."""

_EXTERNAL_REMEMBERED = 4096
"""Checks of refs into external recordings remembered, most recent last."""


class SensorWindow:
    """The sensor messages of the current cycle and of a bounded number of cycles before it.

    ``push`` once per cycle, oldest cycle first, before resolving that cycle's refs.
    Memory is bounded by ``cycles`` cycles of sensor messages (and their digests, each
    computed at most once while the message is in the window: a reading is cited by several
    entities and, for tracked entities, by the cycles after its own).
    """

    __slots__ = ("_batches", "_digests", "_external", "_index", "cycles", "recordings")

    def __init__(
        self, cycles: int = DEFAULT_SENSOR_WINDOW, recordings: Recordings | None = None
    ) -> None:
        if cycles < 0:
            raise ValueError(f"sensor window must be >= 0 cycles, got {cycles}")
        self.cycles = cycles
        self.recordings = recordings
        """External recordings refs may name (None: such refs are unresolved, unchecked)."""
        # (recording, topic, log time, sequence, digest) -> its check, most recent last:
        # tracked entities cite the same reading cycle after cycle
        self._external: OrderedDict[tuple[object, ...], ExternalCheck] = OrderedDict()
        # (topic, log_time_ns) -> the messages logged under it, oldest first
        self._index: dict[tuple[str, int], list[RawMessage]] = {}
        self._batches: deque[Sequence[RawMessage]] = deque()
        # id() of a message in the window -> SHA-256 hex of its data; dropped with the message
        self._digests: dict[int, str] = {}

    def push(self, sensors: Sequence[RawMessage]) -> None:
        """Add one cycle's sensor messages; forget the cycle that falls out of the window."""
        index = self._index
        for msg in sensors:
            key = (msg.topic, msg.log_time_ns)
            entries = index.get(key)
            if entries is None:
                index[key] = [msg]
            else:
                entries.append(msg)
        batches = self._batches
        batches.append(sensors)
        if len(batches) > self.cycles + 1:
            digests = self._digests
            for msg in batches.popleft():
                if digests:
                    digests.pop(id(msg), None)
                key = (msg.topic, msg.log_time_ns)
                entries = index.get(key)
                if entries is not None:
                    del entries[0]
                    if not entries:
                        del index[key]

    def clear(self) -> None:
        self._index.clear()
        self._batches.clear()
        self._digests.clear()

    def resolve(self, ref: Mapping[str, object]) -> str:
        """'' when the ref resolves to a message in the window, else why it does not."""
        if type(ref.get("recording")) is str:
            return self.check_external(ref).detail
        topic = ref.get("topic")
        t_ns = ref.get("log_time_ns")
        if type(topic) is not str or type(t_ns) is not int:
            return "malformed ref (topic or log_time_ns missing)"
        entries = self._index.get((topic, t_ns))
        if not entries:
            return f"no {topic} message at log_time_ns={t_ns} in the sensor window"
        sequence = ref.get("sequence")
        want = ref.get("digest")
        why = ""
        for msg in entries:
            if sequence is not None and msg.sequence != sequence:
                why = why or f"sequence {sequence} does not match the logged {msg.sequence}"
                continue
            if want is not None and self.digest_of(msg) != want:
                why = "digest does not match the logged message data"
                continue
            return ""
        return why

    def check_external(self, ref: Mapping[str, object]) -> ExternalCheck:
        """The check of a ref into an external recording (remembered for the last few
        thousand refs); ``detail`` is '' when it resolved."""
        key = tuple(ref.get(k) for k in ("recording", "topic", "log_time_ns", "sequence", "digest"))
        found = self._external.get(key)
        if found is not None:
            self._external.move_to_end(key)
            return found
        found = check_in_recordings(ref, self.recordings)
        self._external[key] = found
        if len(self._external) > _EXTERNAL_REMEMBERED:
            self._external.popitem(last=False)
        return found

    def unknown(self, ref: Mapping[str, object]) -> bool:
        """True when ``ref`` names a message in an external recording that could not be read
        (not given, not where the log declares it): whether it resolves is unknown."""
        return type(ref.get("recording")) is str and self.check_external(ref).state == "unresolved"

    def external_state(self, ref: Mapping[str, object]) -> ExternalState:
        """resolved, broken or unresolved: what became of a ref into an external recording."""
        return self.check_external(ref).state

    def digest_of(self, msg: RawMessage) -> str:
        """SHA-256 hex of the data of ``msg``, a message in the window (pushed and not yet
        fallen out): computed once while it stays, so the seal check's evidence step reuses
        what resolving refs hashed."""
        found = self._digests.get(id(msg))
        if found is None:
            found = self._digests[id(msg)] = hashlib.sha256(msg.data).hexdigest()
        return found


def check_in_recordings(ref: Mapping[str, object], recordings: Recordings | None) -> ExternalCheck:
    """The check of a ref into an external recording; unresolved says why: not found where
    the log declares it, or (``recordings`` None) not given."""
    if recordings is not None:
        return recordings.check(ref)
    name = str(ref.get("recording"))
    return ExternalCheck(
        "unresolved", name, f"recording {name} not given (the log does not declare it; --evidence)"
    )
