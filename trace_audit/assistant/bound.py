"""An answer's data cut to a size bound, saying per robot what was cut and how to ask for
the rest.

MCP clients cap a message at a few MB, and a model reads little of a long answer; a
timeline of every cycle of a day is hundreds of MB. An answer about several robots is cut
evenly: each robot gets an equal share of the bound (a robot whose answer is smaller keeps
it whole and leaves the rest of its share to the others), so no robot is cut to one row
while another keeps hundreds, which would answer as if the first had no rows. Within a
share (or an answer about one robot) the longest list is cut, again and again, until the
JSON fits; a list whose items name their robots (verify's findings) keeps each robot's
share of items. Each cut is named (where, which robot, kept, total, the time the kept items
reach) with the narrower question that asks for the rest. Lists of a few items are never
cut: fixed-length ones (a pose, a motion) are data, not a listing; nor is a robot's entry
of a list of robots dropped whole.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from typing import Any

import orjson

from trace_audit.log_time import LogClock

__all__ = ["MAX_ANSWER_BYTES", "bound", "rest_of"]

MAX_ANSWER_BYTES = 200_000
"""The largest data an answer carries, as JSON (the answer's text repeats it: ~400 KB)."""
_SHORT = 4
"""Lists this long or shorter are never cut."""
_ROUNDS = 64

Cuts = dict[tuple[str, str | None], dict[str, Any]]
"""The cuts made, by list path and robot (None: the list is not split by robot)."""


def bound(
    data: Any, limit: int = MAX_ANSWER_BYTES, tool: str = ""
) -> tuple[Any, list[dict[str, Any]]]:
    """``data`` (plain JSON values) cut to at most ``limit`` bytes of JSON, and the cuts
    made (``path``, ``robot``, ``kept``, ``total``, ``through``, and ``rest``: how to ask
    ``tool`` for the rest). The data is changed in place. When no list is left to cut, the
    data is None and the cuts say what was tried."""
    cuts: Cuts = {}
    if _size(data) > limit and _is_per_robot(data):
        _share_out(data["robots"], limit - (_size(data) - _size(data["robots"])), cuts)
    fitted = _cut_longest(data, limit, cuts)
    listed = list(cuts.values())
    for cut in listed:
        _attribute(cut, data)
        cut["rest"] = rest_of(tool, cut)
    return fitted, listed


def _size(value: Any) -> int:
    return len(orjson.dumps(value))


def _is_per_robot(data: Any) -> bool:
    """Whether ``data`` is one answer per robot (``selection.PerRobot`` as JSON: each
    answer names its ``robot``; verify's per-robot summaries, ``robot_id``, are not)."""
    answers = data.get("robots") if isinstance(data, dict) else None
    if not isinstance(answers, list) or len(answers) < 2:
        return False
    return _one_per_robot(answers) and all("robot" in answer for answer in answers)


def _robot_of(item: Any) -> str | None:
    """The robot a list's item names (an answer's ``robot``, a finding's ``robot_id``)."""
    if not isinstance(item, dict):
        return None
    robot = item.get("robot", item.get("robot_id"))
    return robot if isinstance(robot, str) else None


def _one_per_robot(items: list[Any]) -> bool:
    robots = [_robot_of(item) for item in items]
    return None not in robots and len(set(robots)) == len(robots)


def _fair(sizes: list[int], budget: int) -> list[int]:
    """Each one's share of ``budget``: equal shares, except that one needing less than its
    share takes what it needs and leaves the rest to the others (water-filling)."""
    shares = [0] * len(sizes)
    left = max(0, budget)
    order = sorted(range(len(sizes)), key=sizes.__getitem__)
    for done, i in enumerate(order):
        shares[i] = min(sizes[i], left // (len(sizes) - done))
        left -= shares[i]
    return shares


def _share_out(answers: list[Any], budget: int, cuts: Cuts) -> None:
    """Each robot's answer cut to its share of ``budget`` bytes (the list's JSON)."""
    sizes = [_size(answer) for answer in answers]
    overhead = _size(answers) - sum(sizes)  # the brackets and commas
    for i, share in enumerate(_fair(sizes, budget - overhead)):
        if sizes[i] > share:  # what does not fit is left to the whole answer's pass
            _cut_longest(answers[i], share, cuts, f"robots[{i}]")


def _cut_longest(value: Any, limit: int, cuts: Cuts, path: str = "") -> Any:
    """``value`` with its longest lists cut until its JSON fits ``limit`` (None if it
    cannot)."""
    for _ in range(_ROUNDS):
        size = _size(value)
        if size <= limit:
            return value
        found = _longest(value, path)
        if found is None:
            break
        where, items, items_size = found
        over = size - limit
        # Keep the share of the list that leaves the rest within the bound (at least one).
        keep = max(1, min(len(items) - 1, int(len(items) * (items_size - over) / items_size)))
        _cut(items, keep, where, cuts)
    return None


def _cut(items: list[Any], keep: int, path: str, cuts: Cuts) -> None:
    """``items`` cut to ``keep``: the first ones, or, when the items name several robots,
    each robot's first ones within its fair share of ``keep``."""
    counts = Counter(_robot_of(item) for item in items)
    if None in counts or len(counts) < 2:
        cut = cuts.setdefault((path, None), {"path": path, "robot": None, "total": len(items)})
        cut["kept"] = keep
        del items[keep:]
        return
    robots = list(counts)
    quota = dict(zip(robots, _fair([counts[r] for r in robots], keep), strict=True))
    seen: Counter[str | None] = Counter()
    kept = []
    for item in items:
        robot = _robot_of(item)
        if seen[robot] < quota[robot]:
            kept.append(item)
        seen[robot] += 1
    for robot in robots:
        if quota[robot] < counts[robot]:
            total = {"path": path, "robot": robot, "total": counts[robot]}
            cuts.setdefault((path, robot), total)["kept"] = quota[robot]
    items[:] = kept


def _longest(value: Any, path: str) -> tuple[str, list[Any], int] | None:
    """The cuttable list whose JSON is largest under ``value``: its path, the list, and its
    size in bytes. A list of robots' entries, one each, is looked into, never cut."""
    best: tuple[str, list[Any], int] | None = None
    stack: list[tuple[Any, str]] = [(value, path)]
    while stack:
        node, where = stack.pop()
        if isinstance(node, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k)) for k, v in node.items())
        elif isinstance(node, list):
            if len(node) > _SHORT and not _one_per_robot(node):
                size = _size(node)
                if best is None or size > best[2]:
                    best = (where, node, size)
            stack.extend((v, f"{where}[{i}]") for i, v in enumerate(node))
    return best


_IN_ROBOT = re.compile(r"robots\[(\d+)\]")


def _attribute(cut: dict[str, Any], data: Any) -> None:
    """The cut's robot (the answer it is in, on an answer per robot) and where its kept
    items end (the last one's cycle and time, in the log's clock), when they say."""
    answer, items, split = data, None, cut["robot"] is not None  # split: items name robots
    found = _IN_ROBOT.match(cut["path"])
    if found and _is_per_robot(data):
        answer = data["robots"][int(found.group(1))]
        cut["robot"] = cut["robot"] or answer["robot"]
    try:
        items = _at(data, cut["path"])
    except (KeyError, IndexError, TypeError):  # cut away by a later cut of its parent
        items = None
    mine = [i for i in items or () if not split or _robot_of(i) == cut["robot"]]
    kept = cut["kept"]
    cut["through"] = _through(mine[kept - 1], answer) if 0 < kept <= len(mine) else None


def _at(data: Any, path: str) -> Any:
    for key, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", path):
        data = data[int(index)] if index else data[key]
    return data


def _through(last: Any, answer: Any) -> str | None:
    """``cycle 368, t 36.8``: the last kept item's cycle and time, the time as a window's
    start or end takes it (ISO on a wall clock)."""
    if not isinstance(last, dict) or type(last.get("t_ns")) is not int:
        return None
    clock: Any = answer.get("clock") if isinstance(answer, dict) else None
    shown = LogClock(clock["name"], clock["start_ns"]) if _is_clock(clock) else None
    end = last.get("end_t_ns")
    t_ns: int = end if type(end) is int else last["t_ns"]
    when = shown.arg(t_ns) if shown else f"{t_ns} ns"
    cycle = last.get("end_cycle", last.get("cycle"))
    return f"cycle {cycle}, t {when}" if type(cycle) is int else f"t {when}"


def _is_clock(clock: Any) -> bool:
    return (
        isinstance(clock, dict)
        and isinstance(clock.get("name"), str)
        and type(clock.get("start_ns")) is int
    )


_NARROWER = {
    "timeline": "a narrower window (start, end)",
    "metrics": "a narrower window (start, end)",
    "check": "a narrower window (start, end)",
    "why": "t (the transition in force then)",
    "find": "a narrower condition (action, near, where) or a smaller limit",
    "query": "a narrower statement",
}
_TAKES_ROBOT = {"why", "explain", "timeline", "metrics", "verify", "check", "find"}


def rest_of(tool: str, cut: dict[str, Any]) -> str:
    """How to ask ``tool`` for what ``cut`` left out: one robot, a narrower question, or the
    command line."""
    robot = cut.get("robot")
    asks = [f"robot {json.dumps([robot])}"] if robot and tool in _TAKES_ROBOT else []
    if tool in _NARROWER:
        asks.append(_NARROWER[tool])
    ask = f"ask {tool} with {' and '.join(asks)}, or " if asks else ""
    return f"{ask}run the reproduce command for all {cut['total']}"
