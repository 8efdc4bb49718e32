"""Metrics benchmark: cycles/s of ``compute_metrics`` on a long simulated log.

    .venv/bin/python bench/bench_metrics.py [--hours 2] [--repeats 3] [--log DIR]

Budget (DESIGN.md): >= 20,000 cycles/s per process; scales across processes.

The log is a sim ``--duration`` run (routine operation, faults at the paper's rates) written
to a log root, which the logger rotates into one segment per simulated hour. It is built
once and kept (``--log``) so repeated runs measure the same bytes.

Measured in the same run, medians of ``--repeats``:
1. anchor: reading alone, every cycle through the reader plus parsing its four layer
   messages and seal (what any metric needs before it computes anything);
2. ``compute_metrics`` in one process, ungrouped and ``--by scenario``;
3. ``compute_metrics`` with ``workers=2``: the segments in two processes.

Ratios are against the anchor and against one process. The machine may be shared and
noisy: compare ratios within a run, not absolute numbers across runs.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import orjson

from sim import RunConfig, run
from trace_audit.metrics import MetricsConfig, compute_metrics
from trace_runtime import open_log

TOPICS = ("/trace/perception", "/trace/belief", "/trace/action", "/trace/execution", "/trace/seal")


def build_log(root: Path, hours: float) -> int:
    """A sim log root of ``hours`` of routine operation (10 Hz); reuse it if present."""
    marker = root / "cycles.txt"
    if marker.exists():
        return int(marker.read_text())
    cycles = round(hours * 36_000)
    print(f"building a {hours:g} h sim log ({cycles} cycles) in {root} ...", flush=True)
    started = time.perf_counter()
    result = run(RunConfig(out=root, total_cycles=cycles, seed=2024))
    print(
        f"  built in {time.perf_counter() - started:.0f} s: {result.written} cycles written,"
        f" {len(result.segments)} segments",
        flush=True,
    )
    marker.write_text(str(result.written))
    return result.written


def read_only(root: Path) -> int:
    """Anchor: iterate every cycle and parse its /trace messages as JSON."""
    n = 0
    for cycle in open_log(root).iter_cycles():
        payloads = cycle.payloads
        for topic in TOPICS:
            data = payloads.get(topic)
            if data is not None:
                orjson.loads(data)
        n += 1
    return n


def _cpu_seconds() -> float:
    """CPU time of this process and of its reaped children (the pool's workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def median_rate(label: str, repeats: int, fn: Callable[[], int]) -> tuple[float, float]:
    """Median cycles/s over ``repeats`` runs, by wall clock and per second of CPU time."""
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), _cpu_seconds()
        n = fn()
        walls.append(n / (time.perf_counter() - wall))
        cpus.append(n / max(_cpu_seconds() - cpu, 1e-9))
    wall_rate, cpu_rate = statistics.median(walls), statistics.median(cpus)
    print(
        f"  {label:<42} wall {wall_rate:>8,.0f}/s  cpu {cpu_rate:>8,.0f}/s"
        f"   (wall runs {min(walls):,.0f}..{max(walls):,.0f})",
        flush=True,
    )
    return wall_rate, cpu_rate


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=2.0, help="simulated hours (default 2)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--log",
        type=Path,
        default=Path("/tmp/trace-bench-metrics"),
        help="where the sim log root is built and kept",
    )
    args = parser.parse_args()

    root = args.log / f"{args.hours:g}h"
    cycles = build_log(root, args.hours)
    segments = sorted(root.rglob("*.mcap"))
    print(
        f"log: {root} ({cycles} cycles, {len(segments)} segments, "
        f"{sum(p.stat().st_size for p in segments) / 1e6:.1f} MB); "
        f"{os.cpu_count()} CPUs; median of {args.repeats}"
    )

    def metrics(config: MetricsConfig) -> Callable[[], int]:
        def go() -> int:
            report = compute_metrics([root], config)
            return report.overall.decisions

        return go

    anchor = median_rate("anchor: read + parse layers", args.repeats, lambda: read_only(root))
    one = median_rate("metrics, 1 process", args.repeats, metrics(MetricsConfig()))
    grouped = median_rate(
        "metrics --by scenario, 1 process",
        args.repeats,
        metrics(MetricsConfig(by="scenario")),
    )
    two = median_rate(
        "metrics, workers=2 (segments in parallel)",
        args.repeats,
        metrics(MetricsConfig(workers=2)),
    )

    print()
    print("cpu = cycles per CPU-second (this process and its pool workers): steadier than")
    print("wall time on a shared machine. The wall speed-up of workers=2 needs idle cores.")
    print(f"metrics / anchor, 1 process (cpu):   {one[1] / anchor[1]:.2f}x")
    print(f"--by scenario / ungrouped (cpu):     {grouped[1] / one[1]:.2f}x")
    print(
        f"2 processes / 1 process (wall):      {two[0] / one[0]:.2f}x over {len(segments)} segments"
    )
    budget = 20_000
    verdict = "meets" if one[1] >= budget else "MISSES"
    print(f"budget >= {budget:,} cycles/s per process (cpu): {verdict} ({one[1]:,.0f})")
    print(f"the anchor alone (read + parse, no metric): {anchor[1]:,.0f} cycles/s (cpu)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
