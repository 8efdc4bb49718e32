"""The Foxglove export and ``timeline`` count a log's decision changes the same way: a
cycle whose command differs from the cycle before it (the first decision of the log is
where it starts, not a change), run from outside on one log and one sim root."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sim import RunConfig, run
from tests.outside import cli
from tests.trace_audit.conftest import write_log


@pytest.mark.parametrize("which", ["fixture", "sim"])
def test_export_and_timeline_count_the_same_changes(tmp_path: Path, which: str) -> None:
    if which == "fixture":
        log: Path = write_log(tmp_path / "run.mcap")
    else:
        log = tmp_path / "root"
        run(RunConfig(out=log, total_cycles=600, seed=5, robot_id="amr-1"))
    timeline = json.loads(cli("timeline", log, "--json").stdout)
    done = cli("export", log, "--format", "foxglove", "--out", tmp_path / "v.mcap", "--json")
    assert done.returncode == 0, done.stderr
    exported = json.loads(done.stdout)
    assert timeline["changes"] > 0
    assert exported["decision_changes"] == timeline["changes"], (exported, timeline["changes"])
