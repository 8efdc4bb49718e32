"""Rules benchmark: ``trace-audit check`` against ``trace-audit metrics`` on the same log, and
``check --index`` over 10 robot-days.

    .venv/bin/python bench/bench_rules.py [--hours 0.25] [--repeats 3] [--log DIR]
                                          [--robot-days 10] [--skip-index]

Targets (issue [rules]): ``check`` with the shipped warehouse rules over a log at least as
fast as ``metrics`` over it (ratio metrics / check >= 1.0); ``check --index`` with five
rules over 10 robot-days (8.64 M decisions) in under 10 s.

The index part indexes the log, then replicates its rows into ``--robot-days`` robot-days
of 864,000 decisions (``bench_fleet.synthesize``: real rows, fresh cycle numbers, times,
segments and robots; no gaps table), and times the whole ``check --index`` process with
the first five warehouse rules, medians of ``--repeats``.

The log is ``bench_metrics``'s sim root (routine operation, faults at the paper's rates),
built once and kept (``--log``). Both commands run as whole processes, in rounds, so a load
change on the shared machine hits both alike; medians of wall and CPU time, the ratio, and
the load average are printed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from bench_metrics import METRICS, REPO, Variant, _children_cpu, build_log

RULES = REPO / "docs" / "rules" / "warehouse.toml"


def measure(variant: Variant) -> None:
    """Run the variant's process once (exit 0, or 1: ``check`` found a violation)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cpu, wall = _children_cpu(), time.perf_counter()
    done = subprocess.run(variant.argv, stdout=subprocess.DEVNULL, env=env, cwd=REPO, check=False)
    if done.returncode not in (0, 1):
        raise SystemExit(f"{variant.label} exited {done.returncode}")
    variant.walls.append(time.perf_counter() - wall)
    variant.cpus.append(_children_cpu() - cpu)


def bench_index(log: Path, robot_days: int, repeats: int) -> None:
    """``check --index`` over ``robot_days`` synthetic robot-days built from ``log``."""
    from bench_fleet import synthesize

    from trace_audit.fleet.index import build_index

    work = log.parent / f"{log.name}-index"
    real, synthetic = work / "real", work / f"days-{robot_days}"
    if not (real / "index.json").exists():
        shutil.rmtree(real, ignore_errors=True)
        build_index([log], real)
    if not (synthetic / "index.json").exists():
        decisions = synthesize(real, synthetic, robot_days)
    else:
        decisions = robot_days * 864_000
    five = work / "five.toml"
    five.write_text("[[rule]]".join(RULES.read_text().split("[[rule]]")[:6]))
    cli = [sys.executable, "-c", METRICS]
    check = Variant(
        "check --index",
        [*cli, "check", "--index", str(synthetic), "--rules", str(five), "--json"],
        [],
        [],
    )
    for _ in range(repeats):
        measure(check)
    print(
        f"  check --index, 5 rules, {robot_days} robot-days ({decisions} decisions): "
        f"wall {check.median_wall():.2f} s  cpu {check.median_cpu():.2f} s  "
        f"{decisions / check.median_wall():,.0f} decisions/s (target < 10 s), "
        f"load {os.getloadavg()[0]:.2f}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=0.25, help="simulated hours")
    parser.add_argument("--repeats", type=int, default=3, help="rounds (medians are taken)")
    parser.add_argument("--log", type=Path, default=Path("/tmp/trace-bench-rules"))
    parser.add_argument("--robot-days", type=int, default=10)
    parser.add_argument("--skip-index", action="store_true", help="only the log part")
    args = parser.parse_args()
    cycles = build_log(args.log, args.hours)
    cli = [sys.executable, "-c", METRICS]
    metrics = Variant("metrics", [*cli, "metrics", str(args.log), "--json"], [], [])
    check = Variant(
        "check", [*cli, "check", str(args.log), "--rules", str(RULES), "--json"], [], []
    )
    for _ in range(args.repeats):
        for variant in (metrics, check):
            measure(variant)
    print(f"{cycles} cycles, {args.repeats} rounds, load {os.getloadavg()[0]:.2f}")
    for v in (metrics, check):
        print(
            f"  {v.label:8s} wall {v.median_wall():6.2f} s  cpu {v.median_cpu():6.2f} s  "
            f"{cycles / v.median_wall():8.0f} cycles/s"
        )
    print(
        f"  metrics / check: cpu {metrics.median_cpu() / check.median_cpu():.2f}x, "
        f"wall {metrics.median_wall() / check.median_wall():.2f}x (target >= 1.0x)"
    )
    if not args.skip_index:
        bench_index(args.log, args.robot_days, args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
