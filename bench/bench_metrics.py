"""Metrics benchmark: ``trace-audit metrics`` against a bare ``mcap`` read + orjson parse.

    .venv/bin/python bench/bench_metrics.py [--hours 2] [--repeats 5] [--log DIR]
        [--anchor all|trace] [--vs TREE] [--no-jobs]

Budgets (DESIGN.md): metrics >= 2x a bare read + JSON parse of the same log; linear in
workers up to the cores available (2 workers >= 1.7x one on a multi-segment root).

The log is a sim ``--duration`` run (routine operation, faults at the paper's rates) written
to a log root, which the logger rotates into one segment per simulated hour. It is built
once and kept (``--log``) so repeated runs measure the same bytes.

Every variant runs as a whole process (interpreter start, imports, opening the log, output),
as a user runs it, in rounds so that a load change on a shared machine hits all alike:

1. anchor: the ``mcap`` library's reader over every segment file, ``orjson.loads`` of every
   message (layers, seals and sensor readings): naively parsing everything; with
   ``--anchor trace``, of every ``/trace`` message only: the shared anchor of
   ``../shared/bench/perf_ratio.py`` (what any metrics implementation must parse);
2. ``trace-audit metrics ROOT --json``: one process;
3. ``trace-audit metrics ROOT --json --jobs 2``: segments spread over two processes
   (left out with ``--no-jobs``);
4. with ``--vs TREE``: the same one-process ``metrics`` from another checkout (``git
   archive REV | tar -x -C TREE``), so a change is measured against its parent in one run.

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

TRACE_ANCHOR = """
import glob, sys, orjson
from mcap.reader import make_reader
n = 0
for p in sorted(glob.glob(sys.argv[1] + "/*/*.mcap")):
    with open(p, "rb") as f:
        for _, c, m in make_reader(f).iter_messages():
            if c.topic.startswith("/trace/"):
                orjson.loads(m.data); n += 1
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
    tree: Path = REPO

    def median_wall(self) -> float:
        return statistics.median(self.walls)

    def median_cpu(self) -> float:
        return statistics.median(self.cpus)


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measure(variant: Variant) -> None:
    """Run the variant's process once; record its wall and CPU seconds."""
    env = {**os.environ, "PYTHONPATH": str(variant.tree)}
    cpu, wall = _children_cpu(), time.perf_counter()
    subprocess.run(variant.argv, check=True, stdout=subprocess.DEVNULL, env=env, cwd=variant.tree)
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
    parser.add_argument(
        "--anchor",
        choices=("all", "trace"),
        default="all",
        help="parse every message (all, default) or every /trace message (trace: the "
        "shared anchor of ../shared/bench/perf_ratio.py)",
    )
    parser.add_argument(
        "--vs", type=Path, help="another checkout whose one-process metrics run beside ours"
    )
    parser.add_argument("--no-jobs", action="store_true", help="leave out the --jobs 2 run")
    args = parser.parse_args()

    root = args.log / f"{args.hours:g}h"
    cycles = build_log(root, args.hours)
    segments = sorted(root.rglob("*.mcap"))
    py = sys.executable
    anchor_code, anchor_label = (
        (TRACE_ANCHOR, "anchor: mcap reader + orjson, /trace msgs")
        if args.anchor == "trace"
        else (ANCHOR, "anchor: mcap reader + orjson, all msgs")
    )
    one_process = [py, "-c", METRICS, "metrics", str(root), "--json"]
    variants = [
        Variant(anchor_label, [py, "-c", anchor_code, str(root)], [], []),
        Variant("metrics, 1 process", one_process, [], []),
    ]
    if not args.no_jobs:
        variants.append(Variant("metrics --jobs 2", [*one_process, "--jobs", "2"], [], []))
    if args.vs is not None:
        variants.append(Variant(f"vs: metrics of {args.vs}", one_process, [], [], args.vs))
    print(
        f"log: {root} ({cycles} cycles, {len(segments)} segments, "
        f"{sum(p.stat().st_size for p in segments) / 1e6:.1f} MB); "
        f"{len(os.sched_getaffinity(0))} CPUs; {args.repeats} rounds, whole processes",
        flush=True,
    )
    loads = []
    for round_no in range(args.repeats):
        # Rotate the order each round: no variant always runs first or after the same one.
        turn = round_no % len(variants)
        for variant in variants[turn:] + variants[:turn]:
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
    anchor, one = variants[0], variants[1]
    print()
    print(
        f"metrics / anchor, 1 process:  cpu {anchor.median_cpu() / one.median_cpu():.2f}x, "
        f"wall {anchor.median_wall() / one.median_wall():.2f}x   (budget >= 2x; "
        f"load average {statistics.median(loads):.2f})"
    )
    if args.vs is not None:
        other = variants[-1]
        print(
            f"{args.vs} / anchor:  cpu {anchor.median_cpu() / other.median_cpu():.2f}x, "
            f"wall {anchor.median_wall() / other.median_wall():.2f}x; ours / theirs, cpu "
            f"{other.median_cpu() / one.median_cpu():.2f}x faster"
        )
    if args.no_jobs:
        return 0
    two = variants[2]
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
