"""Benchmark: ``explain`` at random t on a 24 h log (864,000 cycles) vs a 1-minute log.

Budget (DESIGN.md): explain at t on the 24 h log <= 1.5x the same on the 1-minute log,
both measured here in the same run. Reported per log, as medians over ``--samples`` random
times (the same fractions of each log's range):

- ``call``:  ``explain(path, t=...)`` as the CLI runs it: open the log, seek, reconstruct.
  A log root with a catalog is opened lazily (only the segments the query reaches).
- ``call, all opened``: ``explain(open_log(path), t=...)``: every segment opened first, as
  for a root without a catalog (a hot root straight from the logger).
- ``open``:  ``open_log(path, lazy=True)`` alone (the catalog checked against the files).
- ``first seek``: ``open_log(path, lazy=True).cycle_at(t)``: open plus the first seek into a
  segment, which opens it and loads its chunk table.
- ``hot``:   ``explain(log, t=...)`` on an open ``Log`` whose chunk tables are all loaded:
  what explain itself costs (seek, look-back, chains, graphs, seal check).
- ``seek``:  ``Log.cycle_at(t)`` on that hot ``Log``.

Every measure runs ``--rounds`` times, the two logs alternating, and is timed by the wall
clock or, with ``--clock cpu``, by this process's CPU time (steadier when other work shares
the machine: a wait for a core is not counted, a cache miss is).

Logs are made with the simulator when missing (a log root; the day takes a while: ~10-15
min at ~1,200 cycles/s), and catalogued (``catalog.json``, as compaction or ``trace-audit
catalog`` leaves a root) when they have no catalog. ``--profile`` prints where a day's
``call`` spends its time.

    .venv/bin/python bench/bench_explain.py --clock cpu \
        --day /tmp/explain-bench/day --minute /tmp/explain-bench/minute
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import random
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from trace_audit.explanation import explain
from trace_runtime.reading.logset import open_log
from trace_runtime.tiers.catalog import CATALOG_NAME, refresh_catalog

DAY_CYCLES = 864_000
MINUTE_CYCLES = 600
BUDGET = 1.5


def _ensure(path: Path, cycles: int, seed: int, batch: int) -> None:
    if not path.exists():
        _generate(path, cycles, seed, batch)
    if not (path / CATALOG_NAME).exists():
        print(f"cataloguing {path} (one SHA-256 pass over its files) ...", file=sys.stderr)
        refresh_catalog(path)


def _generate(path: Path, cycles: int, seed: int, batch: int) -> None:
    from sim.runner import RunConfig, run

    print(
        f"generating {path} ({cycles:,} cycles, {batch} per chunk) with the simulator ...",
        file=sys.stderr,
    )
    started = time.perf_counter()
    result = run(RunConfig(out=path, total_cycles=cycles, seed=seed, batch_cycles=batch))
    print(
        f"  {result.written:,} cycles written in {time.perf_counter() - started:.0f} s",
        file=sys.stderr,
    )


CLOCKS: dict[str, Callable[[], float]] = {"wall": time.perf_counter, "cpu": time.process_time}


def _each(
    call: Callable[[int], object], times: list[int], clock: Callable[[], float]
) -> list[float]:
    """Seconds each ``call(t)`` took."""
    out = []
    for t in times:
        started = clock()
        call(t)
        out.append(clock() - started)
    return out


def _samples(path: Path, fractions: list[float], clock: Callable[[], float]) -> dict[str, Any]:
    """One round of every measure on one log: a list of seconds per measure."""
    log = open_log(path)
    start, end = log.start_ns, log.end_ns
    times = [start + int(f * (end - start)) for f in fractions]
    explain(path, t=times[0])  # warm the page cache and imports; not counted
    calls = _each(lambda t: explain(path, t=t), times, clock)
    eager = _each(lambda t: explain(open_log(path), t=t), times, clock)
    opens = _each(lambda _t: open_log(path, lazy=True), times, clock)
    firsts = _each(lambda t: open_log(path, lazy=True).cycle_at(t), times, clock)
    for segment in log.segments:  # load every chunk table: what remains is explain's own
        segment.cycle_at(segment.info.start_ns)
    hot = _each(lambda t: explain(log, t=t), times, clock)
    seeks = _each(log.cycle_at, times, clock)
    return {
        "calls": calls,
        "eager": eager,
        "opens": opens,
        "firsts": firsts,
        "hot": hot,
        "seeks": seeks,
    }


def _measure(path: Path, fractions: list[float], rounds: list[dict[str, Any]]) -> dict[str, Any]:
    log = open_log(path)
    start, end = log.start_ns, log.end_ns
    times = [start + int(f * (end - start)) for f in fractions]
    calls, eager, opens, firsts, hot, seeks = (
        [x for r in rounds for x in r[key]]
        for key in ("calls", "eager", "opens", "firsts", "hot", "seeks")
    )
    held = [explain(log, t=t).held.cycles for t in times]
    chunks = sum(s.info.chunk_count for s in log.segments)
    return {
        "path": str(path),
        "segments": len(log.segments),
        "chunks": chunks,
        "cycles_approx": sum(s.info.channels.get("/trace/seal", 0) for s in log.segments),
        "hours": (end - start) / 3.6e12,
        "call_ms": statistics.median(calls) * 1e3,
        "call_p90_ms": sorted(calls)[int(0.9 * (len(calls) - 1))] * 1e3,
        "call_all_opened_ms": statistics.median(eager) * 1e3,
        "open_ms": statistics.median(opens) * 1e3,
        "first_seek_ms": statistics.median(firsts) * 1e3,
        "hot_ms": statistics.median(hot) * 1e3,
        "seek_ms": statistics.median(seeks) * 1e3,
        "held_cycles_median": statistics.median(held),
    }


def _profile(path: Path, fractions: list[float], top: int) -> str:
    log = open_log(path)
    times = [log.start_ns + int(f * (log.end_ns - log.start_ns)) for f in fractions]
    profiler = cProfile.Profile()
    profiler.enable()
    for t in times:
        explain(path, t=t)
    profiler.disable()
    out = io.StringIO()
    pstats.Stats(profiler, stream=out).sort_stats("cumulative").print_stats(top)
    return out.getvalue()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--day", type=Path, default=Path("/tmp/trace-bench/day"))
    parser.add_argument("--minute", type=Path, default=Path("/tmp/trace-bench/minute"))
    parser.add_argument("--samples", type=int, default=25)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--profile", action="store_true", help="profile the day's calls")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument(
        "--rounds",
        type=int,
        default=3,
        help="rounds of every measure, alternating the two logs, so that a busy spell on a "
        "shared machine falls on both (medians over all rounds)",
    )
    parser.add_argument(
        "--clock",
        choices=sorted(CLOCKS),
        default="wall",
        help="wall: elapsed time; cpu: this process's CPU time (steadier on a shared machine)",
    )
    parser.add_argument(
        "--batch",
        type=int,
        default=1,
        help="cycles per chunk when generating logs (1: as a 10 Hz robot writes; both logs "
        "must be chunked alike for the ratio to mean anything)",
    )
    args = parser.parse_args()
    if args.samples < 20:
        parser.error("--samples must be >= 20")
    _ensure(args.minute, MINUTE_CYCLES, args.seed, args.batch)
    _ensure(args.day, DAY_CYCLES, args.seed, args.batch)
    rng = random.Random(args.seed)
    fractions = [rng.random() for _ in range(args.samples)]
    clock = CLOCKS[args.clock]
    rounds: dict[str, list[dict[str, Any]]] = {"minute": [], "day": []}
    for _ in range(args.rounds):
        rounds["minute"].append(_samples(args.minute, fractions, clock))
        rounds["day"].append(_samples(args.day, fractions, clock))
    minute = _measure(args.minute, fractions, rounds["minute"])
    day = _measure(args.day, fractions, rounds["day"])
    ratios = {
        key: day[key] / minute[key] if minute[key] > 0 else float("inf")
        for key in (
            "call_ms",
            "call_all_opened_ms",
            "open_ms",
            "first_seek_ms",
            "hot_ms",
            "seek_ms",
        )
    }
    result = {
        "samples": args.samples,
        "rounds": args.rounds,
        "clock": args.clock,
        "minute": minute,
        "day": day,
        "ratio": ratios,
        "budget": BUDGET,
        "within_budget": ratios["call_ms"] <= BUDGET,
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(
            f"explain at {args.samples} random t x {args.rounds} alternating rounds, "
            f"{args.clock} clock (medians; same fractions of each range)"
        )
        print(f"{'':14}{'1-minute log':>16}{'24 h log':>16}{'ratio':>10}")
        for key, label in (
            ("call_ms", "call (ms)"),
            ("call_all_opened_ms", "  all opened"),
            ("open_ms", "  open"),
            ("first_seek_ms", "  open+seek"),
            ("hot_ms", "hot explain"),
            ("seek_ms", "  hot seek"),
        ):
            print(f"{label:14}{minute[key]:16.2f}{day[key]:16.2f}{ratios[key]:9.2f}x")
        for key, label in (("segments", "segments"), ("chunks", "chunks")):
            print(f"{label:14}{minute[key]:16,}{day[key]:16,}")
        per_chunk = [
            r["cycles_approx"] / r["chunks"] if r["chunks"] else 0.0 for r in (minute, day)
        ]
        print(f"{'cycles/chunk':14}{per_chunk[0]:16.1f}{per_chunk[1]:16.1f}")
        print(
            f"held-since walk, median cycles: {minute['held_cycles_median']:.0f} (minute), "
            f"{day['held_cycles_median']:.0f} (day)"
        )
        verdict = "within" if result["within_budget"] else "OVER"
        print(f"call ratio {ratios['call_ms']:.2f}x: {verdict} the {BUDGET}x budget")
    if args.profile:
        print(_profile(args.day, fractions, 25))


if __name__ == "__main__":
    main()
