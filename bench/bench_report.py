"""Benchmark: what an incident report costs, part by part, beside ``explain`` on the same log.

For each log (the demo's 500-cycle log, and a log root of ``--hours`` of simulated driving,
made with the simulator when missing) a report is built ``--rounds`` times at the first STOP
(the demo) or the middle of the log (the root), and the medians are printed of:

- ``explain``: ``explain(path, t=...)``, the anchor (the report is built on it);
- ``gather``:  every library call the report makes (explain, timeline, metrics over the
  window, verify of the segments that hold the window, the window's cycles);
- ``verify``:  the verify of those segments alone (usually the largest part of ``gather``);
- ``render``:  drawing the five figures and writing the page;
- the page's size (the issue's budget: under 2 MB for a 30 s window).

    .venv/bin/python bench/bench_report.py --root /tmp/bench/report-1h --hours 1
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from trace_audit.explanation import explain
from trace_audit.incident.data import gather_report
from trace_audit.incident.page import render_page
from trace_runtime.reading.logset import Log, open_log
from trace_runtime.verification import verify

SIZE_BUDGET = 2_000_000


def _timed(call: Callable[[], Any], rounds: int) -> tuple[float, Any]:
    times, result = [], None
    for _ in range(rounds):
        started = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - started)
    return statistics.median(times), result


def _demo(path: Path) -> str:
    from sim.runner import RunConfig, run
    from trace_audit.transitions import why

    if not path.exists():
        run(RunConfig(out=path, scenario="all", cycles=100, seed=42))
    return f"{why(path, 'STOP').transitions[0].t_ns / 1e9:.9g}"


def _root(path: Path, hours: float) -> str:
    from sim.runner import RunConfig, run

    if not path.exists():
        print(f"generating {path} ({hours:g} h) with the simulator ...", file=sys.stderr)
        run(RunConfig(out=path, total_cycles=int(hours * 36_000), seed=5))
    log = open_log(path)
    return f"{(log.start_ns + log.end_ns) / 2e9:.9g}"


def _measure(name: str, path: Path, t: str, rounds: int, window_s: float) -> None:
    anchor, _ = _timed(lambda: explain(path, t=t), rounds)
    gather, data = _timed(lambda: gather_report(path, t=t, window_s=window_s), rounds)
    log = open_log(path)
    scope = [s for s in log.segments if s.end_ns >= data.start_ns and s.start_ns <= data.end_ns]
    checked, _ = _timed(lambda: verify(Log(scope, log.root)), rounds)
    render, html = _timed(lambda: render_page(data), rounds)
    size = len(html.encode())
    cycles = sum(s.info.channels.get("/trace/seal", 0) for s in log.segments)
    print(f"\n{name}: {path} ({cycles:,} sealed cycles, {len(scope)} segment(s) verified)")
    print(f"  explain (anchor)  {anchor * 1e3:9.1f} ms")
    print(f"  gather            {gather * 1e3:9.1f} ms  ({gather / anchor:.1f}x explain)")
    print(f"    of which verify {checked * 1e3:9.1f} ms")
    print(f"  render            {render * 1e3:9.1f} ms")
    print(f"  report in all     {(gather + render) * 1e3:9.1f} ms")
    verdict = "met" if size < SIZE_BUDGET else "NOT met"
    print(f"  page size         {size / 1024:9.1f} KiB, {window_s:g} s window (< 2 MB: {verdict})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demo", type=Path, default=Path("/tmp/bench/report-demo.mcap"))
    parser.add_argument("--root", type=Path, default=Path("/tmp/bench/report-1h"))
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--window", type=float, default=30.0)
    args = parser.parse_args()
    args.demo.parent.mkdir(parents=True, exist_ok=True)
    _measure("demo", args.demo, _demo(args.demo), args.rounds, args.window)
    _measure("root", args.root, _root(args.root, args.hours), args.rounds, args.window)


if __name__ == "__main__":
    main()
