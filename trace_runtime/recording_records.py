"""The record that seals a sensor recording's messages into a robot's chain (profile 1.4).

A robot that records its sensors with another program (rosbag2) cites that recording from its
evidence refs; citing is not enough to protect what no decision cites. The logger follows each
recording it is told about and, on its writer thread, puts into a cycle one ``/trace/recording``
message: the windows of recording time whose messages it has read since the last one (count,
digest and, for locating a change, each message's topic, time, sequence and digest prefix),
messages that landed in a window already sealed (``late``), and what became of a recording
that is not there or stopped growing (``gaps``). The cycle's seal names the message's digest,
so the windows are in the chain like any layer.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from trace_runtime.record_model import RecordModel, Stamp

__all__ = ["TOPIC_RECORDING", "RecordingGap", "RecordingLate", "RecordingSeal", "RecordingWindow"]

TOPIC_RECORDING = "/trace/recording"

_HEX64 = r"^[0-9a-f]{64}$"


class RecordingWindow(RecordModel):
    """Every message of one recording whose log time is in ``[start_ns, end_ns)``."""

    recording: str = Field(min_length=1, description="the recording's name (trace.session)")
    start_ns: int = Field(ge=0, description="the window's first log time, ns (inclusive)")
    end_ns: int = Field(ge=0, description="the window's end, ns (exclusive)")
    count: int = Field(ge=0, description="messages in the window, over all the recording's files")
    digest: str = Field(
        pattern=_HEX64,
        description="sha256 hex over the messages' sensor lines (PROFILE §6) sorted by log time, "
        "topic, sequence and data digest",
    )
    topics: dict[str, int] = Field(description="messages per topic in the window")
    messages: list[tuple[str, int, int, str]] | None = Field(
        default=None,
        description="each message as [topic, log time, sequence, first 16 hex of its data "
        "digest], in the digest's order; null when the window holds more than the writer lists",
    )


class RecordingLate(RecordModel):
    """A message read after its window was sealed (its recorder wrote it out of order)."""

    recording: str = Field(min_length=1, description="the recording's name (trace.session)")
    topic: str = Field(description="the message's topic in the recording")
    log_time_ns: int = Field(ge=0, description="its MCAP log time, ns")
    sequence: int = Field(ge=0, description="its MCAP sequence (0 where its writer sets none)")
    digest: str = Field(pattern=_HEX64, description="sha256 hex of its data")


class RecordingGap(RecordModel):
    """A declared stretch in which a recording could not be sealed: not there (``absent``),
    not growing while the robot ran (``stalled``), growing again (``resumed``), unreadable."""

    recording: str = Field(min_length=1, description="the recording's name (trace.session)")
    state: Literal["absent", "stalled", "resumed", "unreadable"] = Field(
        description="what became of the recording"
    )
    detail: str = Field(default="", description="why, in words")


class RecordingSeal(Stamp):
    """``/trace/recording``: what the writer read of the robot's recordings since the last."""

    windows: list[RecordingWindow] = Field(
        default_factory=list, description="windows of recording time sealed since the last"
    )
    late: list[RecordingLate] = Field(
        default_factory=list, description="messages read after their window was sealed"
    )
    gaps: list[RecordingGap] = Field(
        default_factory=list, description="recordings absent, stalled, resumed or unreadable"
    )
