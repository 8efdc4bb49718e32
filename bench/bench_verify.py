"""Benchmark: ``verify_log`` throughput in cycles/s on a long signed log (default 24 h at 10 Hz).

The log is a log root written through ``AuditLogger`` as a robot would: 10 Hz, 3-5 KB
records (``trace_runtime.testing.synthetic_cycle``) citing a logged LiDAR reading, one chunk
per cycle, hourly segments, Ed25519-signed checkpoints every 10 s. It is generated once and
reused (``--log``). Measured in the same run, medians over ``--repeat`` runs:

- ``verify``: ``verify_log(root, key=...)``: every check (layer and evidence digests, the
  chain, checkpoints, signatures, segment links);
- ``read`` (anchor): ``open_log(root)`` and iterating every cycle: what any pass over the log
  costs before checking anything;
- ``hash`` (anchor): ``read`` plus SHA-256 of every message, the least a chain check must do.

    .venv/bin/python bench/bench_verify.py --hours 24 --log /tmp/bench/verify-day
    .venv/bin/python bench/bench_verify.py --hours 0.5 --repeat 5
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

from trace_audit.verify import verify_log
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.records import Evidence, Perception
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tlog.keys import generate_keypair, load_public_key

PERIOD_NS = 100_000_000
START_NS = 1_700_000_000_000_000_000


def generate(root: Path, cycles: int) -> Path:
    """Write ``cycles`` signed cycles into the log root; return the public key's path."""
    keys = generate_keypair(root / "keys")
    config = LoggerConfig(
        threaded=False,
        fsync_interval_s=None,
        max_segment_s=3600.0,
        checkpoint_interval_s=10.0,
        checkpoint_key=keys.private_path,
    )
    variants = [synthetic_cycle(i) for i in range(50)]  # records drift smoothly; reuse them
    started = time.perf_counter()
    with AuditLogger(root, robot_id="amr-bench", period_s=0.1, config=config) as logger:
        for i in range(cycles):
            perception, belief, action, execution = variants[i % len(variants)]
            with logger.cycle(START_NS + i * PERIOD_NS) as c:
                ref = c.sensor("/sensors/lidar", {"ranges": [1.0 + (i % 97) / 50, 2.5], "i": i})
                entities = [
                    e.model_copy(
                        update={"evidence": [Evidence(sensor="lidar", weight=1.0, ref=ref)]}
                    )
                    for e in perception.entities
                ]
                c.perception(Perception(entities=entities, sensors_used=["lidar"]))
                c.belief(belief)
                c.action(action)
                c.execution(execution)
            if i and i % 100_000 == 0:
                rate = i / (time.perf_counter() - started)
                print(f"  {i:,} cycles ({rate:,.0f}/s)", file=sys.stderr)
    return keys.public_path


def _median(call: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Median wall time and median CPU time of ``repeat`` calls (the machine may be shared)."""
    wall, cpu = [], []
    for _ in range(repeat):
        started, started_cpu = time.perf_counter(), time.process_time()
        call()
        wall.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
    return statistics.median(wall), statistics.median(cpu)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=24.0, help="log length at 10 Hz")
    parser.add_argument("--log", type=Path, default=None, help="log root (made if missing)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = parser.parse_args(argv)
    cycles = round(args.hours * 36_000)
    root = args.log or Path(f"/tmp/bench/verify-{args.hours:g}h")
    public = root / "keys" / "trace-ed25519.pub"
    if not public.exists():
        print(f"generating {root} ({cycles:,} cycles) ...", file=sys.stderr)
        started = time.perf_counter()
        public = generate(root, cycles)
        print(f"  done in {time.perf_counter() - started:.0f} s", file=sys.stderr)
    key = load_public_key(public)

    report = verify_log(root, key=key)
    if not report.ok:
        print(f"the benchmark log does not verify: {report.findings[:3]}", file=sys.stderr)
        return 1
    n = report.cycles

    def read() -> None:
        for _cycle in open_log(root).iter_cycles():
            pass

    def hashed() -> None:
        sha = hashlib.sha256
        for cycle in open_log(root).iter_cycles():
            for data in cycle.payloads.values():
                sha(data).digest()
            for message in cycle.sensors:
                sha(message.data).digest()

    t_verify, c_verify = _median(lambda: verify_log(root, key=key), args.repeat)
    t_read, c_read = _median(read, args.repeat)
    t_hash, c_hash = _median(hashed, args.repeat)
    size = sum(p.stat().st_size for p in root.rglob("*.mcap"))
    result = {
        "cycles": n,
        "segments": len(report.segments),
        "checkpoints": report.checkpoints,
        "log_bytes": size,
        "verify_s": round(t_verify, 3),
        "verify_cycles_per_s": round(n / t_verify),
        "read_cycles_per_s": round(n / t_read),
        "hash_cycles_per_s": round(n / t_hash),
        "verify_over_read": round(t_verify / t_read, 2),
        "verify_over_hash": round(t_verify / t_hash, 2),
        "verify_cpu_cycles_per_s": round(n / c_verify),
        "read_cpu_cycles_per_s": round(n / c_read),
        "hash_cpu_cycles_per_s": round(n / c_hash),
        "verify_over_read_cpu": round(c_verify / c_read, 2),
        "repeat": args.repeat,
    }
    if args.json:
        print(json.dumps(result))
        return 0
    print(
        f"log: {root} ({n:,} cycles, {result['segments']} segments, "
        f"{report.checkpoints:,} signed checkpoints, {size / 1e6:,.0f} MB)"
    )
    print(
        f"  verify (all checks, signatures)  {result['verify_cycles_per_s']:>10,} cycles/s"
        f"  ({t_verify:.1f} s)"
    )
    print(
        f"  anchor: read every cycle         {result['read_cycles_per_s']:>10,} cycles/s"
        f"  (verify = {result['verify_over_read']}x read)"
    )
    print(
        f"  anchor: read + SHA-256 of all    {result['hash_cycles_per_s']:>10,} cycles/s"
        f"  (verify = {result['verify_over_hash']}x hash)"
    )
    print(
        f"  CPU time: verify {result['verify_cpu_cycles_per_s']:,}, read "
        f"{result['read_cpu_cycles_per_s']:,}, hash {result['hash_cpu_cycles_per_s']:,} "
        f"cycles/s (verify = {result['verify_over_read_cpu']}x read)"
    )
    print(f"  medians of {args.repeat} runs (wall and CPU time)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
