"""A decoded sensor message shown in full: as bounded, typed JSON for scripts and as a few
readable lines for people, with the part of it a decision cited (its evidence's region).

``message_data`` turns a decoded message (a ROS 2 message as ``mcap-ros2-support`` builds it,
or parsed JSON) into JSON values: numbers stay numbers, arrays arrays, nested messages
objects, ``uint8[]`` bytes their length and a hex head. A message may be a camera image or
a point cloud, so everything is bounded: an array keeps its first ``MAX_ITEMS`` elements, a
message its first ``MAX_VALUES`` values, ``MAX_DEPTH`` levels; what is cut is marked
``{"truncated": true, "length": N, "items": [...]}``. JSON has no infinity: a non-finite
float (a scan's "no return") is null.

``message_lines`` says what a person asks of the common sensor types, read by their fields
(not their type names, so a JSON reading of the same shape reads the same): a scan's
beams and nearest return, each detection's class, score and box, joint states, odometry;
any other message its top-level fields. ``cited_region`` reads the cited region (PROFILE
§3: beams, box, cone, pixels) against the message: the beams' ranges and bearings, or the
detection whose box the cited box overlaps most.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "BYTES_HEAD",
    "MAX_DEPTH",
    "MAX_ITEMS",
    "MAX_VALUES",
    "CitedRegion",
    "cited_region",
    "message_data",
    "message_lines",
]

MAX_ITEMS = 1024
"""Elements kept of one array."""
MAX_VALUES = 65536
"""Values (numbers, strings, bools, byte strings) kept of one message, in field order."""
MAX_DEPTH = 32
"""Levels of nesting kept (a ROS type is rarely deeper than 6)."""
BYTES_HEAD = 32
"""Bytes of a ``uint8[]`` field shown as hex."""

_MAX_TEXT = 60
_MAX_FIELDS = 12
_MAX_LINES_ITEMS = 8
"""Detections or joints written out for people; the rest counted."""


def fields_of(value: object) -> list[tuple[str, object]]:
    """A message's fields in order: a dict's items, or a ROS 2 message's slots."""
    if isinstance(value, Mapping):
        return [(str(k), v) for k, v in value.items()]
    slots = getattr(value, "__slots__", None) or list(getattr(value, "__dict__", {}))
    return [(name, getattr(value, name)) for name in slots if not name.startswith("_")]


def _field(value: object, name: str) -> object:
    """A field of a dict or a ROS 2 message; None when it has none of that name."""
    if isinstance(value, Mapping):
        return value.get(name)
    if value is None or isinstance(value, str | bytes | int | float | list | tuple):
        return None
    return getattr(value, name, None)


def _number(value: object) -> float | None:
    """A finite number (a bool is not one), else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _text(value: object) -> str | None:
    return value if isinstance(value, str) else None


# --- the message as JSON ------------------------------------------------------------------------


def message_data(value: object) -> Any:
    """``value`` as bounded JSON values (see the module's docstring)."""
    return _Budget(MAX_VALUES).data(value, 0)


class _Budget:
    """How many values may still be kept of one message."""

    __slots__ = ("left",)

    def __init__(self, left: int) -> None:
        self.left = left

    def data(self, value: object, depth: int) -> Any:
        if value is None or isinstance(value, bool | str | int | float | bytes | bytearray):
            return self._scalar(value)
        if depth >= MAX_DEPTH:
            return {"truncated": True}
        if isinstance(value, list | tuple):
            return self._array(value, depth)
        if self.left <= 0:
            return {"truncated": True}
        return {name: self.data(item, depth + 1) for name, item in fields_of(value)}

    def _scalar(self, value: object) -> Any:
        self.left -= 1
        if isinstance(value, bytes | bytearray):
            return {"bytes": len(value), "head": bytes(value[:BYTES_HEAD]).hex()}
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    def _array(self, value: Sequence[object], depth: int) -> Any:
        kept: list[Any] = []
        for item in value[:MAX_ITEMS]:
            if self.left <= 0:
                break
            kept.append(self.data(item, depth + 1))
        if len(kept) == len(value):
            return kept
        return {"truncated": True, "length": len(value), "items": kept}


# --- the message for people ---------------------------------------------------------------------


def message_lines(value: object) -> tuple[str, ...]:
    """What a person reads of a decoded message: the common sensor types by their fields,
    any other message its top-level fields on one line."""
    for view in (_scan_lines, _detection_lines, _joint_lines, _odometry_lines):
        lines = view(value)
        if lines:
            return lines
    return (", ".join(f"{name}={short(item)}" for name, item in fields_of(value)[:_MAX_FIELDS]),)


def short(value: object) -> str:
    """One field as at most 60 characters: scalars as they are, arrays by length and first
    elements, bytes by length, nested messages by their first fields."""
    if isinstance(value, float):
        text = f"{value:.6g}"
    elif isinstance(value, bytes | bytearray):
        text = f"{len(value)} bytes"
    elif isinstance(value, list | tuple):
        head = ", ".join(short(v) for v in value[:4])
        text = f"[{len(value)}] {head}{', …' if len(value) > 4 else ''}"
    elif isinstance(value, str | int | bool) or value is None:
        text = repr(value) if isinstance(value, str) else str(value)
    else:
        text = "{" + ", ".join(f"{k}: {short(v)}" for k, v in fields_of(value)[:3]) + "}"
    return text if len(text) <= _MAX_TEXT else text[: _MAX_TEXT - 1] + "…"


def _scan_lines(value: object) -> tuple[str, ...]:
    """A LaserScan: beam count and field of view, the nearest and farthest returns."""
    ranges = _field(value, "ranges")
    first, step = _number(_field(value, "angle_min")), _number(_field(value, "angle_increment"))
    if not isinstance(ranges, list | tuple) or first is None or step is None:
        return ()
    finite = [(r, i) for i, v in enumerate(ranges) if (r := _number(v)) is not None]
    if not finite:
        return (f"{len(ranges)} beams, no return",)
    (low, at), (high, _) = min(finite), max(finite)
    last = first + step * max(len(ranges) - 1, 0)
    lines = [
        f"{len(ranges)} beams from {first:.3f} to {last:.3f} rad; ranges {low:.3f}..{high:.3f} m,"
        f" nearest {low:.3f} m at beam {at} ({first + step * at:.3f} rad)"
    ]
    if len(finite) < len(ranges):
        missing = len(ranges) - len(finite)
        lines.append(f"{missing} beam{'s' if missing > 1 else ''} without a return")
    return tuple(lines)


def _detections(value: object) -> list[object]:
    """The detections of a Detection2DArray/3DArray, or the one detection a message is."""
    many = _field(value, "detections")
    if isinstance(many, list | tuple):
        return list(many)
    return [value] if _field(value, "bbox") is not None else []


def _detection_lines(value: object) -> tuple[str, ...]:
    """Each detection's best class and score, and its box."""
    found = _detections(value)
    if not found and _field(value, "detections") is None:
        return ()
    lines = [f"{len(found)} detections"] if len(found) != 1 else []
    for detection in found[:_MAX_LINES_ITEMS]:
        cls, score = _best_hypothesis(detection)
        box = _box(detection)
        ident = _text(_field(detection, "id"))
        shown = f"{cls or '?'} score {score:.2f}" if score is not None else f"{cls or '?'}"
        where = " box " + ", ".join(f"{v:g}" for v in box) if box else ""
        lines.append(f"{shown}{where}" + (f" (id {ident})" if ident else ""))
    if len(found) > _MAX_LINES_ITEMS:
        lines.append(f"… and {len(found) - _MAX_LINES_ITEMS} more")
    return tuple(lines)


def _best_hypothesis(detection: object) -> tuple[str | None, float | None]:
    """The class and score of a detection's best result (vision_msgs 3+: results[].
    hypothesis.class_id/score; 2.x: results[].id/score)."""
    best: tuple[str | None, float | None] = (None, None)
    results = _field(detection, "results")
    for result in results if isinstance(results, list | tuple) else ():
        hypothesis = _field(result, "hypothesis") or result
        cls = _text(_field(hypothesis, "class_id")) or _text(_field(hypothesis, "id"))
        score = _number(_field(hypothesis, "score"))
        if best[1] is None or (score is not None and score > best[1]):
            best = (cls, score)
    return best


def _box(detection: object) -> tuple[float, ...]:
    """A 2D detection's box as (xmin, ymin, xmax, ymax) in its image, () when it has none."""
    bbox = _field(detection, "bbox")
    center = _field(bbox, "center") if bbox is not None else None
    position = _field(center, "position") or center  # vision_msgs 3+ nests a Point2D
    x, y = _number(_field(position, "x")), _number(_field(position, "y"))
    w, h = _number(_field(bbox, "size_x")), _number(_field(bbox, "size_y"))
    if x is None or y is None or w is None or h is None:
        return ()
    return (x - w / 2, y - h / 2, x + w / 2, y + h / 2)


def _joint_lines(value: object) -> tuple[str, ...]:
    """JointState: each joint's position, velocity and effort, by name."""
    names = _field(value, "name")
    if not isinstance(names, list | tuple) or _field(value, "position") is None:
        return ()
    columns = [(key, _field(value, key)) for key in ("position", "velocity", "effort")]
    lines = []
    for i, name in enumerate(names[:_MAX_LINES_ITEMS]):
        parts = [
            f"{key} {v:.4g}"
            for key, column in columns
            if isinstance(column, list | tuple)
            and i < len(column)
            and (v := _number(column[i])) is not None
        ]
        lines.append(f"{name}: {', '.join(parts) or 'no values'}")
    if len(names) > _MAX_LINES_ITEMS:
        lines.append(f"… and {len(names) - _MAX_LINES_ITEMS} more joints")
    return tuple(lines)


def _odometry_lines(value: object) -> tuple[str, ...]:
    """Odometry: the pose's position and the twist's linear x and angular z."""
    twist = _field(_field(value, "twist"), "twist")
    pose = _field(_field(value, "pose"), "pose")
    if twist is None or pose is None:
        return ()
    position = _field(pose, "position")
    linear, angular = _field(twist, "linear"), _field(twist, "angular")
    xyz = [_number(_field(position, k)) for k in ("x", "y", "z")]
    return (
        "position " + ", ".join("?" if v is None else f"{v:.3f}" for v in xyz) + " m; "
        f"linear x {_shown(_field(linear, 'x'))} m/s, angular z {_shown(_field(angular, 'z'))}"
        " rad/s",
    )


def _shown(value: object) -> str:
    number = _number(value)
    return "?" if number is None else f"{number:.4g}"


# --- the part a decision cited ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class CitedRegion:
    """The region an evidence item cites (PROFILE §3, ``Region``), read against its message.

    ``part`` is what the region selects there, as JSON: for beams (or a cone) of a scan,
    ``first``/``last`` beam and their ``ranges`` and ``bearings_rad``; for a box or pixels
    over detections, the detection it overlaps most (``class``, ``score``, ``box``,
    ``overlap`` as intersection over union); None when the message has nothing to select.
    ``text`` says it in one line for people."""

    kind: str
    values: tuple[float, ...]
    frame: str
    part: Any
    text: str


def cited_region(region: object, value: object | None) -> CitedRegion | None:
    """The evidence item's ``region`` (JSON) read against the decoded message ``value``
    (None: not decoded); None when the item cites no region."""
    if not isinstance(region, Mapping):
        return None
    kind = _text(region.get("kind")) or "?"
    raw = region.get("values")
    values = tuple(v for v in (raw if isinstance(raw, list) else ()) if _number(v) is not None)
    frame = _text(region.get("frame")) or ""
    named = f"{kind} [{', '.join(f'{v:g}' for v in values)}]" + (f" in {frame}" if frame else "")
    part: Any = None
    text = f"cited {named}"
    if value is not None and kind in ("beams", "cone"):
        part, said = _cited_beams(kind, values, value)
        text += f": {said}" if said else ""
    elif value is not None and kind in ("box", "pixels"):
        part, said = _cited_detection(values, value)
        text += f": {said}" if said else ""
    return CitedRegion(kind, tuple(float(v) for v in values), frame, part, text)


def _cited_beams(
    kind: str, values: tuple[float, ...], scan: object
) -> tuple[dict[str, Any] | None, str]:
    """The beams a ``beams`` [first, last] or ``cone`` [bearing, half width, range] region
    selects of a scan, their ranges and bearings."""
    ranges = _field(scan, "ranges")
    first_rad, step = _number(_field(scan, "angle_min")), _number(_field(scan, "angle_increment"))
    if not isinstance(ranges, list | tuple) or not ranges or first_rad is None or not step:
        return None, ""
    if kind == "beams" and len(values) >= 2:
        lo, hi = int(values[0]), int(values[1])
    elif kind == "cone" and len(values) >= 2:
        lo = math.ceil((values[0] - values[1] - first_rad) / step)
        hi = math.floor((values[0] + values[1] - first_rad) / step)
    else:
        return None, ""
    lo, hi = max(lo, 0), min(hi, len(ranges) - 1)
    if lo > hi:
        return None, "outside the scan's beams"
    picked = list(ranges[lo : hi + 1][:MAX_ITEMS])
    bearings = [first_rad + step * i for i in range(lo, lo + len(picked))]
    shown = [_number(r) for r in picked]
    part = {"first": lo, "last": hi, "ranges": shown, "bearings_rad": bearings}
    finite = [r for r in shown if r is not None]
    near = f", nearest {min(finite):.3f} m" if finite else ", no return"
    return part, (
        f"beams {lo}..{hi} ({bearings[0]:.3f}..{bearings[-1]:.3f} rad): "
        + ", ".join("inf" if r is None else f"{r:.2f}" for r in shown[:_MAX_FIELDS])
        + (" …" if len(picked) > _MAX_FIELDS else "")
        + " m"
        + near
    )


def _cited_detection(
    values: tuple[float, ...], message: object
) -> tuple[dict[str, Any] | None, str]:
    """The detection whose box the cited box overlaps most (intersection over union)."""
    if len(values) < 4:
        return None, ""
    scored = [(_overlap(values[:4], box), d, box) for d in _detections(message) if (box := _box(d))]
    if not scored:
        return None, ""
    overlap, detection, box = max(scored, key=lambda s: s[0])
    if overlap <= 0:
        return None, "overlaps no detection"
    cls, score = _best_hypothesis(detection)
    part = {"class": cls, "score": score, "box": list(box), "overlap": overlap}
    said = f"{cls or '?'}" + (f" score {score:.2f}" if score is not None else "")
    return part, f"detection {said} (box overlap {overlap:.2f})"


def _overlap(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Intersection over union of two boxes (xmin, ymin, xmax, ymax)."""
    ax0, ay0, ax1, ay1 = a
    bx0, by0, bx1, by1 = b
    w = max(0.0, min(ax1, bx1) - max(ax0, bx0))
    h = max(0.0, min(ay1, by1) - max(ay0, by0))
    union = (ax1 - ax0) * (ay1 - ay0) + (bx1 - bx0) * (by1 - by0) - w * h
    return w * h / union if union > 0 else 0.0
