"""An answer's data cut to a size bound, saying what was cut.

MCP clients cap a message at a few MB, and a model reads little of a long answer; a
timeline of every cycle of a day is hundreds of MB. So the longest list is cut, again and
again, until the JSON fits, and each cut is named (where, kept, total). Lists of a few items
are never cut: fixed-length ones (a pose, a motion) are data, not a listing.
"""

from __future__ import annotations

from typing import Any

import orjson

__all__ = ["MAX_ANSWER_BYTES", "bound"]

MAX_ANSWER_BYTES = 200_000
"""The largest data an answer carries, as JSON (the answer's text repeats it: ~400 KB)."""
_SHORT = 4
"""Lists this long or shorter are never cut."""
_ROUNDS = 64


def bound(data: Any, limit: int = MAX_ANSWER_BYTES) -> tuple[Any, list[dict[str, Any]]]:
    """``data`` (plain JSON values) cut to at most ``limit`` bytes of JSON, and the cuts
    made (``path``, ``kept``, ``total``). The data is changed in place. When no list is
    left to cut, the data is None and the cuts say what was tried."""
    cuts: dict[str, dict[str, Any]] = {}
    for _ in range(_ROUNDS):
        size = len(orjson.dumps(data))
        if size <= limit:
            return data, list(cuts.values())
        found = _longest(data, "")
        if found is None:
            break
        path, items, items_size = found
        over = size - limit
        # Keep the share of the list that leaves the rest within the bound (at least one).
        keep = max(1, min(len(items) - 1, int(len(items) * (items_size - over) / items_size)))
        cut = cuts.setdefault(path, {"path": path, "kept": keep, "total": len(items)})
        cut["kept"] = keep
        del items[keep:]
    return None, list(cuts.values())


def _longest(value: Any, path: str) -> tuple[str, list[Any], int] | None:
    """The cuttable list whose JSON is largest under ``value``: its path, the list, and its
    size in bytes."""
    best: tuple[str, list[Any], int] | None = None
    stack: list[tuple[Any, str]] = [(value, path)]
    while stack:
        node, where = stack.pop()
        if isinstance(node, dict):
            stack.extend((v, f"{where}.{k}" if where else str(k)) for k, v in node.items())
        elif isinstance(node, list):
            if len(node) > _SHORT:
                size = len(orjson.dumps(node))
                if best is None or size > best[2]:
                    best = (where, node, size)
            stack.extend((v, f"{where}[{i}]") for i, v in enumerate(node))
    return best
