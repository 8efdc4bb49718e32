"""Metric values are pinned: ``metrics --json --failures`` on small honest sim logs gives
exactly the values recorded in ``data/metrics_golden/golden.json`` (every field but timing).

The golden file was written by the code before the metrics fast path (commit 92ec0c0), so a
speed-up that changes any value (a float's last bit included) fails here. The logs and the
runs are in ``golden.py``; regenerate only when a definition changes on purpose.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.trace_audit.metrics.golden import DATA, GOLDEN, RUNS, metrics_json

_GOLDEN = json.loads(GOLDEN.read_text())


def test_every_run_has_a_golden_value() -> None:
    assert sorted(_GOLDEN) == sorted(RUNS)


@pytest.mark.parametrize("name", sorted(RUNS))
def test_metrics_json_matches_the_golden_values(name: str, tmp_path: Path) -> None:
    # Read from a copy elsewhere: the values must not depend on where the log lives.
    base = tmp_path / "data"
    shutil.copytree(DATA, base, ignore=shutil.ignore_patterns("golden.json"))
    assert metrics_json(base, RUNS[name]) == _GOLDEN[name]
