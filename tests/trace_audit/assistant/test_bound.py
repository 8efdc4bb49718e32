"""An answer cut to its size bound: the longest lists first, each cut named, short lists
(a pose, a motion) left whole; an answer about several robots cut evenly across them."""

from __future__ import annotations

import orjson

from trace_audit.assistant.bound import bound, rest_of


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
    [made] = cuts
    assert made == {"path": "robots[0].rows", "robot": None, "kept": len(rows), "total": 5000,
                    "through": None, "rest": "run the reproduce command for all 5000"}  # fmt: skip
    assert cut["robots"][0]["gaps"] == _rows(20)  # what fitted stays whole
    assert all(r["pose"] == [1.0, 2.0, 3.0] for r in rows)


def test_several_lists_are_cut_when_one_is_not_enough() -> None:
    cut, cuts = bound({"a": _rows(3000), "b": _rows(3000)}, 10_000)
    assert len(orjson.dumps(cut)) <= 10_000
    assert {c["path"] for c in cuts} == {"a", "b"}
    assert all(c["total"] == 3000 and c["kept"] < 3000 for c in cuts)


def test_an_answer_with_nothing_to_cut_is_none() -> None:
    assert bound({"text": "x" * 50_000}, 10_000) == (None, [])


def _robot(name: str, rows: int) -> dict[str, object]:
    """One robot's answer in an answer per robot (``selection.PerRobot`` as JSON)."""
    listed = [{"cycle": i, "t_ns": i * 100_000_000, "command": "GO"} for i in range(rows)]
    return {"robot": name, "clock": {"name": "sim", "start_ns": 0}, "rows": listed}


def test_an_answer_per_robot_is_cut_evenly_and_each_cut_names_its_robot() -> None:
    """Found from outside: one robot kept 1 row of 3000 while another kept 366 of 1800."""
    data = {"path": "fleet", "robots": [_robot("amr-1", 3000), _robot("amr-2", 1800)]}
    cut, cuts = bound(data, 40_000, "timeline")
    assert len(orjson.dumps(cut)) <= 40_000
    kept = [len(r["rows"]) for r in cut["robots"]]
    assert min(kept) > 0.9 * max(kept), kept  # rows of one size: equal shares, equal rows
    assert len(orjson.dumps(cut)) > 0.8 * 40_000  # the bound is used, not wasted
    rest = 'ask timeline with robot ["{}"] and a narrower window (start, end), or run the '
    assert cuts == [
        {"path": "robots[0].rows", "robot": "amr-1", "kept": kept[0], "total": 3000,
         "through": f"cycle {kept[0] - 1}, t {(kept[0] - 1) / 10:g}",
         "rest": rest.format("amr-1") + "reproduce command for all 3000"},
        {"path": "robots[1].rows", "robot": "amr-2", "kept": kept[1], "total": 1800,
         "through": f"cycle {kept[1] - 1}, t {(kept[1] - 1) / 10:g}",
         "rest": rest.format("amr-2") + "reproduce command for all 1800"},
    ]  # fmt: skip
    assert cut["robots"][1]["rows"] == _robot("amr-2", kept[1])["rows"]  # the first, in order


def test_a_robot_under_its_share_keeps_all_and_leaves_the_rest_to_the_others() -> None:
    data = {"robots": [_robot("a", 3000), _robot("b", 20), _robot("c", 3000)]}
    cut, cuts = bound(data, 60_000)
    assert len(orjson.dumps(cut)) <= 60_000
    a, b, c = (len(r["rows"]) for r in cut["robots"])
    assert b == 20 and [x["robot"] for x in cuts] == ["a", "c"]
    assert abs(a - c) <= 0.1 * a and a > 20 * 5


def test_a_list_whose_items_name_robots_keeps_each_robots_share() -> None:
    def findings() -> list[dict[str, object]]:
        ones = [{"robot_id": "amr-1", "kind": "modified", "cycle": i} for i in range(2000)]
        return ones + [{"robot_id": "amr-2", "kind": "gap", "cycle": i} for i in range(300)]

    cut, cuts = bound({"findings": findings()}, 20_000)
    assert len(orjson.dumps(cut)) <= 20_000
    by_robot = {r: [f for f in cut["findings"] if f["robot_id"] == r] for r in ("amr-1", "amr-2")}
    ones, twos = len(by_robot["amr-1"]), len(by_robot["amr-2"])
    assert abs(ones - twos) <= 1 and ones > 50
    assert by_robot["amr-2"] == findings()[2000 : 2000 + twos]  # each robot's first, in order
    assert [(c["robot"], c["kept"], c["total"]) for c in cuts] == [
        ("amr-1", ones, 2000), ("amr-2", twos, 300),
    ]  # fmt: skip


def test_no_robot_is_dropped_whole_from_an_answer_of_many() -> None:
    data = {"robots": [_robot(f"amr-{i}", 400) for i in range(8)]}
    cut, cuts = bound(data, 30_000)
    assert len(orjson.dumps(cut)) <= 30_000
    assert [r["robot"] for r in cut["robots"]] == [f"amr-{i}" for i in range(8)]
    assert all(len(r["rows"]) >= 5 for r in cut["robots"])
    assert len(cuts) == 8


def test_the_rest_is_asked_of_one_robot_with_a_narrower_question() -> None:
    cut = {"path": "robots[1].rows", "robot": "amr-2", "kept": 10, "total": 1800}
    assert rest_of("timeline", cut) == (
        'ask timeline with robot ["amr-2"] and a narrower window (start, end), '
        "or run the reproduce command for all 1800"
    )
    alone = {"path": "rows", "robot": None, "kept": 10, "total": 99}
    assert rest_of("explain", alone) == "run the reproduce command for all 99"


def test_a_verify_report_keeps_each_robots_summary_and_share_of_findings() -> None:
    """verify's JSON is no answer per robot: its per-robot summaries stay whole, its findings
    and segments (each naming its robot) are cut robot by robot, and the answer's first
    line says so."""
    from trace_audit.assistant.integrity import unverified
    from trace_audit.assistant.server import _result

    def finding(robot: str, i: int) -> dict[str, object]:
        return {"robot_id": robot, "kind": "modified", "first_cycle": i, "message": "x" * 80}

    report = {
        "robots": [{"robot_id": r, "cycles": 9000, "announced_keys": []} for r in ("a", "b")],
        "findings": [finding("a", i) for i in range(3000)] + [finding("b", i) for i in range(40)],
    }
    cut, cuts = bound(report, 20_000, "verify")
    assert [r["robot_id"] for r in cut["robots"]] == ["a", "b"]
    assert [(c["path"], c["robot"], c["total"]) for c in cuts] == [("findings", "a", 3000)]
    rest = 'ask verify with robot ["a"], or run the reproduce command for all 3000'
    assert cuts[0]["rest"] == rest
    assert sum(f["robot_id"] == "b" for f in cut["findings"]) == 40  # under its share: whole
    lead = _result(unverified("test"), "trace-audit verify x --json", cut, cuts).content[0]
    assert "a findings " in getattr(lead, "text", "") and 'robot ["a"]' in getattr(lead, "text", "")
