"""The one segment file-name rule: how a segment's file is named, and how a name is read back.

A log root names each robot's segments ``<tier>/<robot>_<number>.mcap`` with the segment number
zero-padded to at least six digits; a log written to a single file path rotates to
``<stem>.<number>.mcap`` beside it. The logger builds names here, resume and compaction read
them back here, so a name one of them accepts the others accept too.
"""

from __future__ import annotations

import re

__all__ = [
    "SEGMENT_SUFFIX",
    "parse_segment_name",
    "rotated_segment_name",
    "segment_name",
]

SEGMENT_SUFFIX = ".mcap"
_DIGITS = 6
_NAME = re.compile(rf"(?P<robot>.+)_(?P<number>\d{{{_DIGITS},}})\.mcap")


def segment_name(robot_id: str, number: int) -> str:
    """The file name of ``robot_id``'s segment ``number`` in a log root's tier folder."""
    return f"{robot_id}_{number:0{_DIGITS}d}{SEGMENT_SUFFIX}"


def rotated_segment_name(stem: str, number: int) -> str:
    """The file name of segment ``number`` (> 0) of a log written to the single file ``stem``."""
    return f"{stem}.{number:0{_DIGITS}d}{SEGMENT_SUFFIX}"


def parse_segment_name(name: str) -> tuple[str, int] | None:
    """(robot id, segment number) of a log root's segment file name; None for any other name."""
    match = _NAME.fullmatch(name)
    return None if match is None else (match["robot"], int(match["number"]))
