"""Benchmark: simulated + logged cycles per second in routine operation (``--duration`` mode).

Budget: >= 5,000 cycles/s simulated and logged (a 24 h run, 864,000 cycles, in < 3 min).

In the same run, as anchors:
- the logger alone: the very records of the sim run replayed through ``AuditLogger``
  (synchronous, as the sim uses it), to show how the time splits between the simulator
  and the logger;
- the sim's share, derived as 1 / (1/total - 1/logger).

Run: ``.venv/bin/python bench/bench_sim.py [--cycles 20000]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import orjson

from sim import RunConfig, run
from trace_runtime import AuditLogger, LoggerConfig, open_log

LAYERS = ("/trace/perception", "/trace/belief", "/trace/action", "/trace/execution")


def _replay_logger(log_path: Path, out: Path, limit: int) -> float:
    """Cycles/s of the logger alone on the records the sim wrote."""
    cycles = []
    for c in open_log(log_path).iter_cycles():
        layers = {}
        for topic in LAYERS:
            msg = c.json(topic)
            msg.pop("cycle")
            msg.pop("t_ns")
            layers[topic] = msg
        cycles.append((layers, [(m.topic, orjson.loads(m.data)) for m in c.sensors]))
        if len(cycles) >= limit:
            break
    logger = AuditLogger(out, robot_id="bench", clock="sim",
                         config=LoggerConfig(threaded=False, fsync_interval_s=None))
    start = time.perf_counter()
    for k, (layers, sensors) in enumerate(cycles):
        with logger.cycle(k * 100_000_000) as c:
            for topic, payload in sensors:
                c.sensor(topic, payload)
            c.perception(layers["/trace/perception"])
            c.belief(layers["/trace/belief"])
            c.action(layers["/trace/action"])
            c.execution(layers["/trace/execution"])
    logger.close()
    return len(cycles) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.mcap"
        result = run(RunConfig(out=out, total_cycles=args.cycles, seed=args.seed))
        total = result.cycles_per_s
        logger_only = _replay_logger(out, Path(tmp) / "replay.mcap", min(args.cycles, 5000))
    sim_only = 1.0 / max(1e-12, 1.0 / total - 1.0 / logger_only)
    per_cycle = result.bytes_written / max(1, result.written)
    day_s = 864_000 / total
    print(f"cycles             {result.cycles:,} (dropped {result.dropped})")
    print(f"sim + logging      {total:,.0f} cycles/s  (budget >= 5,000)  "
          f"-> 24 h of operation in {day_s / 60:.1f} min")
    print(f"logger alone       {logger_only:,.0f} cycles/s  (same records, synchronous)")
    print(f"sim alone (derived){sim_only:,.0f} cycles/s")
    print(f"bytes per cycle    {per_cycle:,.0f} B (MCAP, zstd chunks)")
    print("verdict            " + ("PASS" if total >= 5000 else "FAIL (under 5,000 cycles/s)"))


if __name__ == "__main__":
    main()
