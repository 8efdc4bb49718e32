"""An answer cut to its size bound: the longest lists first, each cut named, short lists
(a pose, a motion) left whole."""

from __future__ import annotations

import orjson

from trace_audit.assistant.bound import bound


def _rows(n: int) -> list[dict[str, object]]:
    return [{"cycle": i, "command": "STOP", "pose": [1.0, 2.0, 3.0]} for i in range(n)]


def test_a_small_answer_is_left_whole() -> None:
    data = {"rows": _rows(10)}
    assert bound(data, 100_000) == ({"rows": _rows(10)}, [])


def test_the_longest_list_is_cut_to_fit_and_the_cut_is_named() -> None:
    data = {"robots": [{"robot": "amr-7", "rows": _rows(5000), "gaps": _rows(20)}]}
    cut, cuts = bound(data, 20_000)
    assert len(orjson.dumps(cut)) <= 20_000
    rows = cut["robots"][0]["rows"]
    assert rows == _rows(len(rows))  # the first rows, in order
    assert cuts == [{"path": "robots[0].rows", "kept": len(rows), "total": 5000}]
    assert cut["robots"][0]["gaps"] == _rows(20)  # what fitted stays whole
    assert all(r["pose"] == [1.0, 2.0, 3.0] for r in rows)


def test_several_lists_are_cut_when_one_is_not_enough() -> None:
    cut, cuts = bound({"a": _rows(3000), "b": _rows(3000)}, 10_000)
    assert len(orjson.dumps(cut)) <= 10_000
    assert {c["path"] for c in cuts} == {"a", "b"}
    assert all(c["total"] == 3000 and c["kept"] < 3000 for c in cuts)


def test_an_answer_with_nothing_to_cut_is_none() -> None:
    assert bound({"text": "x" * 50_000}, 10_000) == (None, [])
