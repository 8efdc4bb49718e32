"""timeline: rows per decision change (or per cycle), leading factor, flags, gaps."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import PERIOD_NS, stretch, t_ns, write_log
from trace_audit.cli import app
from trace_audit.jsonout import to_jsonable
from trace_audit.transitions import timeline
from trace_runtime.errors import UsageError


def test_a_row_per_decision_change(sample_log: Path) -> None:
    r = timeline(sample_log)
    assert [(row.cycle, row.command, row.cycles) for row in r.rows] == [
        (0, "CONTINUE", 30),
        (30, "SLOW", 10),
        (40, "STOP", 20),
        (60, "CONTINUE", 10),
        (70, "REROUTE", 10),
        (80, "STOP", 5),
        (85, "CONTINUE", 15),
    ]
    assert r.cycles == 100 and r.changes == 6 and r.gaps == ()
    assert sum(row.held_ns for row in r.rows) == 100 * PERIOD_NS
    stop = r.rows[2]
    assert stop.previous == "SLOW" and stop.leading is not None
    assert (stop.leading.name, stop.leading.value, stop.leading.unit) == ("distance", 1.5, "m")
    assert r.rows[4].leading is not None and r.rows[4].leading.name == "aisle_blocked"
    assert stop.scenario == "ped_close" and stop.flag_counts == {}


def test_every_gives_a_row_per_cycle(sample_log: Path) -> None:
    r = timeline(sample_log, every=True)
    assert len(r.rows) == 100 and r.changes == 6
    assert all(row.cycles == 1 for row in r.rows)


def test_window_by_absolute_and_relative_time(sample_log: Path) -> None:
    r = timeline(sample_log, start="+3.5", end=t_ns(72))
    assert [row.cycle for row in r.rows] == [35, 40, 60, 70]
    assert r.rows[0].command == "SLOW" and r.rows[0].previous is None
    assert r.cycles == 72 - 35 + 1


def test_flags_are_counted_over_the_stretch(tmp_path: Path) -> None:
    log = write_log(
        tmp_path / "r.mcap",
        [stretch("clear", 4), stretch("clear", 3, "flag"), stretch("ped_close", 2)],
    )
    rows = timeline(log).rows
    assert rows[0].flag_counts == {"deviation_high": 3} and rows[0].flagged_cycles == 3
    assert rows[1].flag_counts == {}


def test_dropped_cycles_show_as_gaps(tmp_path: Path) -> None:
    log = write_log(tmp_path / "r.mcap", [stretch("clear", 20)], skip=lambda i: i in (5, 6, 7))
    r = timeline(log)
    (gap,) = r.gaps
    assert (gap.after_cycle, gap.before_cycle, gap.declared_dropped) == (4, 8, 3)
    assert gap.interval_ns == 4 * PERIOD_NS and gap.gap_ns == 3 * PERIOD_NS
    assert gap.missing_cycles == 3
    assert r.cycles == 17 and len(r.rows) == 1


def test_window_errors(sample_log: Path) -> None:
    with pytest.raises(UsageError, match="ends before it starts"):
        timeline(sample_log, start="+5", end="+2")
    with pytest.raises(UsageError, match="does not overlap"):
        timeline(sample_log, start="500", end="600")


def test_a_restarted_clock_gives_one_sequence_per_run_never_merged_by_time(
    tmp_path: Path,
) -> None:
    """Two runs of one robot whose times overlap (a restart with a monotonic clock): each
    run's rows are its own, its first row is no decision change, and the text shows the
    runs one after the other."""
    root = write_log(tmp_path / "root")
    write_log(root)
    alone = timeline(write_log(tmp_path / "one.mcap"))
    both = timeline(root)
    assert [(r.first_cycle, r.last_cycle, r.cycles) for r in both.clock_runs] == [
        (0, 99, 100),
        (100, 199, 100),
    ]
    assert both.changes == 2 * alone.changes and both.cycles == 200
    runs = [row.run for row in both.rows]
    assert runs == sorted(runs) and set(runs) == {0, 1}
    second = [row for row in both.rows if row.run == 1]
    assert second[0].previous is None and second[0].cycle == 100
    assert "clock_runs" not in to_jsonable(alone) and "run" not in to_jsonable(alone.rows[0])
    shown = CliRunner().invoke(app, ["timeline", str(root), "--plain"]).output
    assert shown.index("clock run 1 of 2") < shown.index("clock run 2 of 2")
