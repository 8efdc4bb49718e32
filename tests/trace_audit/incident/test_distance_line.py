"""The report's factor figure over a sim run where one pedestrian leaves and the next
scenario's arrives: ``distance`` is read from ``ped_1.distance``, then ``ped_2.distance``.
The line breaks there (NaN), so the page never draws one person approaching."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

from sim import RunConfig, run
from trace_audit.incident.data import gather_report
from trace_audit.incident.time_figures import factor_line


def test_the_distance_line_breaks_where_the_pedestrian_changes(tmp_path: Path) -> None:
    run(RunConfig(out=tmp_path / "root", total_cycles=260, seed=3, robot_id="amr-1"))
    data = gather_report(tmp_path / "root", cycle=205, window_s=20.0)
    nodes = [(s.cycle, s.factor_nodes.get("distance")) for s in data.samples]
    changes = [
        cycle
        for (_, a), (cycle, b) in itertools.pairwise(nodes)
        if a is not None and b is not None and a != b
    ]
    assert changes, nodes  # the run does hand over from one pedestrian to the next
    xs, ys = factor_line(data, "distance")
    for cycle in changes:
        t = next(s.t_ns for s in data.samples if s.cycle == cycle)
        at = data.explanation.log_clock
        x = (t - at.start_ns) / 1e9 if at.wall else t / 1e9
        i = xs.index(x)
        assert math.isnan(ys[i]) and not math.isnan(ys[i + 1]), (cycle, ys[i - 1 : i + 2])
    assert sum(math.isnan(y) for y in ys) >= len(changes)
