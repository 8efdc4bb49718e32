"""Metrics on a root of several robots: answered per robot unless a grouping is asked for,
``robots`` reading exactly the robots named, an unknown robot refused with the log's list."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.trace_audit.conftest import T0_NS, stretch, write_log
from trace_audit.jsonout import to_jsonable
from trace_audit.metrics import MetricsConfig, compute_metrics
from trace_runtime.errors import UsageError

SECOND = (stretch("clear", 25), stretch("ped_close", 15, "null_ref"))
"""amr-2's script: 40 cycles, some not traceable, so its figures differ from amr-1's."""


@pytest.fixture
def fleet(tmp_path: Path) -> Path:
    """amr-1 (the default 100-cycle script) and amr-2 (40 cycles, 50 ms later) in one root."""
    root = tmp_path / "fleet"
    write_log(root, robot_id="amr-1")
    write_log(root, SECOND, robot_id="amr-2", t0_ns=T0_NS + 50_000_000)
    return root


def test_several_robots_are_answered_per_robot(fleet: Path) -> None:
    report = compute_metrics([fleet])
    assert report.by == "robot"
    assert [(g.name, g.decisions) for g in report.groups] == [("amr-1", 100), ("amr-2", 40)]
    assert report.overall.decisions == 140 and report.robots == ()


def test_a_grouping_asked_for_is_kept(fleet: Path) -> None:
    report = compute_metrics([fleet], MetricsConfig(by="scenario"))
    assert report.by == "scenario"
    assert "amr-1" not in {g.name for g in report.groups}


def test_one_robot_of_a_root_gives_its_own_log_figures(fleet: Path, tmp_path: Path) -> None:
    alone = tmp_path / "alone"
    write_log(alone, SECOND, robot_id="amr-2", t0_ns=T0_NS + 50_000_000)
    selected = compute_metrics([fleet], robots=["amr-2"])
    own = compute_metrics([alone])
    assert selected.robots == ("amr-2",)
    assert selected.by is None and selected.groups == ()
    assert selected.overall.decisions == 40
    assert to_jsonable(selected.overall) == to_jsonable(own.overall)
    assert [s.rsplit("/", 1)[-1] for s in selected.segments] == ["amr-2_000000.mcap"]
    assert [(f.cycle, f.problems) for f in selected.failures] == [
        (f.cycle, f.problems) for f in own.failures
    ]


def test_naming_every_robot_is_the_whole_root(fleet: Path) -> None:
    both = compute_metrics([fleet], robots=["amr-2", "amr-1"])
    whole = compute_metrics([fleet])
    assert both.robots == ("amr-2", "amr-1")
    assert to_jsonable(both.groups) == to_jsonable(whole.groups)


def test_an_unknown_robot_is_refused_naming_the_robots(fleet: Path) -> None:
    with pytest.raises(UsageError, match=r"'amr-9' .*amr-1, amr-2"):
        compute_metrics([fleet], robots=["amr-9"])


def test_one_robot_log_is_not_grouped(tmp_path: Path) -> None:
    report = compute_metrics([write_log(tmp_path / "one")])
    assert report.by is None and report.groups == () and report.across_groups is None
