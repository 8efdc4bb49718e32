"""The golden metric values of ``test_golden.py``: the logs, the runs, regeneration.

    PYTHONPATH=. python -m tests.trace_audit.metrics.golden   # rewrite logs and golden.json

The logs are small honest sim runs (fault injection on, nothing tampered), stored as files
so the golden values pin the reader and the metrics, not the simulator's random draws:
``run.mcap`` (one file, heavy faults) and ``root/`` (robot amr-01 in two segments, the
second a restart that continues its chain, and robot amr-02 in one). Regenerate only when a
metric's definition changes on purpose, and say so in the commit.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from typer.testing import CliRunner

DATA = Path(__file__).parents[1] / "data" / "metrics_golden"
GOLDEN = DATA / "golden.json"

RUNS: dict[str, tuple[str, ...]] = {
    "file": ("run.mcap",),
    "file_by_scenario": ("run.mcap", "--by", "scenario"),
    "file_jobs2": ("run.mcap", "--jobs", "2"),
    "root": ("root",),
    "root_by_robot": ("root", "--by", "robot"),
    "root_by_scenario": ("root", "--by", "scenario"),
    "root_by_segment": ("root", "--by", "segment"),
    "root_by_hour": ("root", "--by", "hour"),
    "root_jobs2": ("root", "--jobs", "2"),
    "root_by_robot_jobs2": ("root", "--by", "robot", "--jobs", "2"),
    "root_by_scenario_jobs2": ("root", "--by", "scenario", "--jobs", "2"),
    "root_window": ("root", "--start", "4", "--end", "8", "--sensor-window", "1"),
}
"""Name -> arguments after ``trace-audit metrics`` (paths relative to ``DATA``)."""

TIMING_FIELDS = ("elapsed_s", "cycles_per_s", "logging_time", "logging_cost")
"""Fields that measure the run, not the log (``table_ii.time_per_cycle`` too)."""


def metrics_json(base: Path, args: tuple[str, ...]) -> dict[str, Any]:
    """``trace-audit metrics ARGS --json --failures`` with paths under ``base``, timing
    fields dropped and ``base`` written as ``<data>``."""
    from trace_audit.cli import app

    argv = [str(base / args[0]), *args[1:], "--json", "--failures"]
    result = CliRunner().invoke(app, ["metrics", *argv])
    assert result.exit_code == 0, result.stdout + result.stderr
    data: dict[str, Any] = json.loads(result.stdout.replace(str(base), "<data>"))
    for name in TIMING_FIELDS:
        data.pop(name, None)
    data["table_ii"].pop("time_per_cycle")
    return data


def build_logs(base: Path) -> None:
    """Write ``run.mcap`` and ``root/`` under ``base`` with the simulator."""
    from sim import FaultRates, RunConfig, run

    heavy = FaultRates(
        lidar_unavailable=0.05,
        camera_unavailable=0.15,
        evidence_corruption=0.08,
        edge_write_failure=0.08,
        rationale_truncation=0.06,
        counterfactual_timeout=0.06,
        audit_write_timeout=0.04,
    )
    # Eight cycles a chunk keeps the files small (one a chunk compresses poorly).
    run(RunConfig(out=base / "run.mcap", cycles=20, seed=11, faults=heavy, batch_cycles=8))
    root = base / "root"
    run(RunConfig(out=root, cycles=10, seed=12, batch_cycles=8))
    run(RunConfig(out=root, cycles=8, seed=13, start_ns=6_000_000_000, batch_cycles=8))
    run(
        RunConfig(
            out=root, cycles=10, seed=14, robot_id="amr-02", start_ns=2_000_000_000, batch_cycles=8
        )
    )
    # Only the segments are the fixture: no truth sidecars, no lock files.
    extras = [*base.glob("*.truth.jsonl"), *base.glob(".*.lock"), root / "truth", root / ".locks"]
    for extra in extras:
        if extra.is_dir():
            shutil.rmtree(extra)
        elif extra.exists():
            extra.unlink()


def main() -> None:
    if DATA.exists():
        shutil.rmtree(DATA)
    DATA.mkdir(parents=True)
    build_logs(DATA)
    golden = {name: metrics_json(DATA, args) for name, args in RUNS.items()}
    GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
