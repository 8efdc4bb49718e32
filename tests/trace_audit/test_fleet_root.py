"""Many robots in one root, from the outside: no command mixes robots or picks one silently.

The root holds three robots written by the fixture logger on one clock (amr-1 and amr-2
overlap in time, amr-3 runs later), the arm example (a profile 1.1 robot whose times count
from zero) and a tractor on the wall clock. Every command runs as a user runs it, in a
fresh process.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
from html import unescape
from pathlib import Path

import pytest

from tests.outside import REPO, cli, one_line
from tests.trace_audit.conftest import write_log
from trace_audit.incident.data import gather_report
from trace_audit.jsonout import to_jsonable
from trace_audit.log_time import LogClock

SIM_ROBOTS = ("amr-1", "amr-2", "amr-3")
WALL_T0_NS = 1_777_874_400 * 10**9  # 2026-05-04T06:00:00Z


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("fleet") / "root"
    write_log(root, robot_id="amr-1")  # t = 100.0 .. 109.9 s
    write_log(root, robot_id="amr-2", t0_ns=105 * 10**9)  # 105.0 .. 114.9 s
    write_log(root, robot_id="amr-3", t0_ns=200 * 10**9)  # 200.0 .. 209.9 s
    write_log(root, robot_id="tractor-1", t0_ns=WALL_T0_NS)
    subprocess.run(
        [sys.executable, str(REPO / "examples" / "pick_and_place_arm.py"), "--out", str(root)],
        check=True,
        capture_output=True,
        cwd=REPO,
    )
    return root


def _json(*args: str | Path) -> dict:
    done = cli(*args, "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_a_time_two_robots_share_is_refused_naming_them(fleet: Path) -> None:
    one_line(cli("explain", fleet, "--t", "106"), 2, "amr-1, amr-2", "--robot")
    one_line(cli("report", fleet, "--t", "106", "--out", fleet.parent / "r.html"), 2, "amr-1")
    one_line(cli("export", fleet, "--t", "106"), 2, "amr-1, amr-2")
    one_line(cli("explain", fleet, "--cycle", "5"), 2, "robots have a cycle numbered 5")


def test_a_time_only_one_robot_has_is_that_robots_decision(fleet: Path) -> None:
    only = _json("explain", fleet, "--t", "203")
    assert (only["robot"], only["cycle"], only["clock_run"]) == ("amr-3", 30, [])
    chosen = _json("explain", fleet, "--t", "106", "--robot", "amr-2")
    assert (chosen["robot"], chosen["cycle"]) == ("amr-2", 10)
    one_line(cli("explain", fleet, "--t", "106", "--robot", "amr-9"), 2, "'amr-9' is not in")


def test_questions_over_time_are_answered_per_robot(fleet: Path) -> None:
    why = _json("why", fleet, "--action", "STOP")
    # the arm never STOPs
    assert [r["robot"] for r in why["robots"]] == ["amr-1", "amr-2", "amr-3", "tractor-1"]
    for answer in why["robots"]:
        alone = _json("why", fleet, "--action", "STOP", "--robot", answer["robot"])
        assert alone == answer
    info = _json("info", fleet, "--quick")
    robots = [r["robots"] for r in info["robots"]]
    assert robots == [["amr-1"], ["amr-2"], ["amr-3"], ["arm-1"], ["tractor-1"]]
    assert all(len({s["robot"] for s in r["segments"]}) == 1 for r in info["robots"])


def test_a_timeline_never_interleaves_robots(fleet: Path) -> None:
    both = _json("timeline", fleet, "--from", "104", "--to", "106")
    assert [r["robot"] for r in both["robots"]] == ["amr-1", "amr-2"]  # the others miss it
    for answer in both["robots"]:
        alone = write_log(
            fleet.parent / f"{answer['robot']}.mcap",
            robot_id=answer["robot"],
            t0_ns=(100 if answer["robot"] == "amr-1" else 105) * 10**9,
        )
        assert (
            answer["cycles"] == _json("timeline", alone, "--from", "104", "--to", "106")["cycles"]
        )
    picked = _json("timeline", fleet, "--robot", "amr-2", "--from", "104", "--to", "106")
    assert picked == both["robots"][1]


def test_a_wall_clock_is_read_and_shown_as_iso(fleet: Path) -> None:
    clock = LogClock("system", WALL_T0_NS)
    assert clock.wall and not LogClock("system", 0).wall  # the arm's clock counts from zero
    moment = WALL_T0_NS + 5_000_000_000
    assert clock.iso(moment) == "2026-05-04T06:00:05Z"
    by_iso = _json("explain", fleet, "--robot", "tractor-1", "--t", "2026-05-04T08:00:05+02:00")
    by_offset = _json("explain", fleet, "--robot", "tractor-1", "--t", "+5")
    assert by_iso["cycle"] == by_offset["cycle"] == 50 and by_iso["query_t_ns"] == moment
    shown = cli("explain", fleet, "--robot", "tractor-1", "--t", "+5", "--plain").stdout
    assert f"t={clock.iso(moment, digits=3)} (+5.000 s)" in shown.splitlines()[0]
    one_line(
        cli("explain", fleet, "--robot", "amr-1", "--t", clock.iso(moment)), 2, "not times of day"
    )


def _reproduce(page: Path) -> list[list[str]]:
    text = page.read_text(encoding="utf-8")
    start = text.index('id="reproduce"')
    blocks = text[start:].split("<pre>")[1:]
    return [shlex.split(unescape(b.split("</pre>")[0])) for b in blocks]


def test_the_reports_commands_reproduce_its_decision_and_window(fleet: Path) -> None:
    page = fleet.parent / "tractor.html"
    summary = _json("report", fleet, "--robot", "tractor-1", "--t", "+5.55", "--out", page)
    commands = {c[1]: c[1:] for c in _reproduce(page)}
    assert set(commands) >= {"explain", "timeline", "verify", "metrics", "export", "report"}
    assert not any("e+09" in arg for args in commands.values() for arg in args)
    explained = _json(*commands["explain"])
    assert (explained["robot"], explained["cycle"]) == (summary["robot"], summary["cycle"])
    window = _json(*commands["timeline"])
    assert (window["start_ns"], window["end_ns"]) == (
        summary["window_start_ns"],
        summary["window_end_ns"],
    )
    assert window["cycles"] == summary["cycles_in_window"]
    scored = _json(*commands["metrics"])
    page_figures = gather_report(fleet, robots=["tractor-1"], t="+5.55").metrics.overall
    assert scored["overall"] == to_jsonable(page_figures)
    assert scored["overall"]["decisions"] == summary["cycles_in_window"]
    again = _json(*commands["report"], "--out", fleet.parent / "again.html")
    assert {k: again[k] for k in ("robot", "cycle", "window_start_ns", "window_end_ns")} == {
        k: summary[k] for k in ("robot", "cycle", "window_start_ns", "window_end_ns")
    }


def test_a_time_is_read_in_each_robots_own_clock(fleet: Path) -> None:
    # +5 is five seconds into each robot's own log: every robot has a decision then
    one_line(cli("explain", fleet, "--t", "+5"), 2, "5 robots have a decision at +5")
    # an ISO time is a moment only to the robot on a wall clock
    iso = _json("explain", fleet, "--t", "2026-05-04T06:00:05Z")
    assert (iso["robot"], iso["cycle"]) == ("tractor-1", 50)
    # seconds in no robot's range: each robot's range is named
    one_line(cli("explain", fleet, "--t", "99999"), 2, "no robot has a decision at 99999", "amr-3")
    per_robot = _json("timeline", fleet, "--from", "+2", "--to", "+3")
    firsts = {r["robot"]: r["rows"][0]["cycle"] for r in per_robot["robots"]}
    assert firsts == {r: 20 for r in ("amr-1", "amr-2", "amr-3", "arm-1", "tractor-1")}
    # one window for every robot scored: +offset needs one robot, ISO wall-clock robots
    one_line(cli("metrics", fleet, "--start", "+2"), 2, "choose one with --robot")
    one_line(cli("metrics", fleet, "--start", "2026-05-04T06:00:02Z"), 2, "amr-1", "no wall")
    alone = _json("metrics", fleet, "--robot", "tractor-1", "--start", "+2", "--end", "+3")
    assert alone["overall"]["decisions"] == 11


def test_a_metrics_window_that_misses_every_robot_is_a_usage_error(fleet: Path) -> None:
    done = cli("metrics", fleet, "--robot", "amr-1", "--start", "500", "--end", "600")
    one_line(done, 2, "holds no decision of the log", "amr-1 100.000 s .. 109.900 s")
