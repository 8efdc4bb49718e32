"""Metrics benchmark: ``trace-audit metrics`` against a bare ``mcap`` read + orjson parse.

    .venv/bin/python bench/bench_metrics.py [--hours 2] [--repeats 5] [--log DIR]

Budgets (DESIGN.md): metrics >= 2x a bare read + JSON parse of the same log; linear in
workers up to the cores available (2 workers >= 1.7x one on a multi-segment root).

The log is a sim ``--duration`` run (routine operation, faults at the paper's rates) written
to a log root, which the logger rotates into one segment per simulated hour. It is built
once and kept (``--log``) so repeated runs measure the same bytes.

Every variant runs as a whole process (interpreter start, imports, opening the log, output),
as a user runs it, in rounds so that a load change on a shared machine hits all alike:

1. anchor: the ``mcap`` library's reader over every segment file, ``orjson.loads`` of every
   message (layers, seals and sensor readings): naively parsing everything;
2. ``trace-audit metrics ROOT --json``: one process;
3. ``trace-audit metrics ROOT --json --jobs 2``: segments spread over two processes.

Reported: medians of wall time and of CPU time (the process and its children), cycles/s,
and the ratios metrics / anchor (CPU, and wall) and 2 workers / 1 (wall). CPU ratios are
the steadier ones on a shared machine; the wall speed-up of workers needs idle cores, so
the load average is printed beside it.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from sim import RunConfig, run

REPO = Path(__file__).resolve().parent.parent

ANCHOR = """
import sys
from pathlib import Path

import orjson
from mcap.reader import make_reader

cycles = 0
for path in sorted(Path(sys.argv[1]).rglob("*.mcap")):
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            orjson.loads(message.data)
            cycles += channel.topic == "/trace/seal"
print(cycles)
"""

METRICS = "import sys; from trace_audit.cli import main; sys.exit(main())"


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


@dataclass
class Variant:
    label: str
    argv: list[str]
    walls: list[float]
    cpus: list[float]

    def median_wall(self) -> float:
        return statistics.median(self.walls)

    def median_cpu(self) -> float:
        return statistics.median(self.cpus)


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measure(variant: Variant) -> None:
    """Run the variant's process once; record its wall and CPU seconds."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cpu, wall = _children_cpu(), time.perf_counter()
    subprocess.run(variant.argv, check=True, stdout=subprocess.DEVNULL, env=env, cwd=REPO)
    variant.walls.append(time.perf_counter() - wall)
    variant.cpus.append(_children_cpu() - cpu)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=2.0, help="simulated hours (default 2)")
    parser.add_argument("--repeats", type=int, default=5, help="rounds (medians are taken)")
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
    py = sys.executable
    variants = [
        Variant("anchor: mcap reader + orjson, all msgs", [py, "-c", ANCHOR, str(root)], [], []),
        Variant("metrics, 1 process", [py, "-c", METRICS, "metrics", str(root), "--json"], [], []),
        Variant(
            "metrics --jobs 2",
            [py, "-c", METRICS, "metrics", str(root), "--json", "--jobs", "2"],
            [],
            [],
        ),
    ]
    print(
        f"log: {root} ({cycles} cycles, {len(segments)} segments, "
        f"{sum(p.stat().st_size for p in segments) / 1e6:.1f} MB); "
        f"{len(os.sched_getaffinity(0))} CPUs; {args.repeats} rounds, whole processes",
        flush=True,
    )
    loads = []
    for round_no in range(args.repeats):
        # Rotate the order each round: no variant always runs first or after the same one.
        for variant in variants[round_no % 3 :] + variants[: round_no % 3]:
            measure(variant)
        loads.append(os.getloadavg()[0])
        print(
            f"  round {round_no + 1}: "
            + ", ".join(f"{v.label.split(':')[0]} {v.walls[-1]:.2f}s" for v in variants)
            + f" (load {loads[-1]:.2f})",
            flush=True,
        )

    print()
    print(f"{'':<42} {'wall s':>7} {'cpu s':>7} {'cycles/s wall':>14} {'cycles/s cpu':>13}")
    for v in variants:
        print(
            f"{v.label:<42} {v.median_wall():>7.2f} {v.median_cpu():>7.2f}"
            f" {cycles / v.median_wall():>14,.0f} {cycles / v.median_cpu():>13,.0f}"
        )
    anchor, one, two = variants
    print()
    print(
        f"metrics / anchor, 1 process:  cpu {anchor.median_cpu() / one.median_cpu():.2f}x, "
        f"wall {anchor.median_wall() / one.median_wall():.2f}x   (budget >= 2x)"
    )
    print(
        f"2 workers / 1, wall:          {one.median_wall() / two.median_wall():.2f}x over "
        f"{len(segments)} segments   (budget >= 1.7x; "
        f"load average {statistics.median(loads):.2f} on {len(os.sched_getaffinity(0))} CPUs)"
    )
    print(
        f"2 workers, cpu overhead:      {two.median_cpu() / one.median_cpu():.2f}x the CPU "
        "of one process (what a second worker costs in total work)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
