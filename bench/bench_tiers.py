"""Storage tiers benchmark: bytes per cycle of every storage form, compaction and read speed.

    .venv/bin/python bench/bench_tiers.py [--hours 1] [--repeats 3] [--jobs 2] [--log DIR]
                                          [--json results.json]

Budgets (DESIGN.md): cold <= 0.5x MCAP default zstd chunks and <= 0.8x whole-stream
zstd -19, lossless. Compaction speed against its budget (>= 0.5x a bare read + parse + dump
+ zstd-3 rewrite, 2 workers >= 1.7x one) and the cold first seek are measured, as whole
processes on a multi-segment root, by ``bench/bench_compaction.py``.

Three logs, built once and kept under ``--log``: (a) a long routine-operation sim run
(``trace-sim run --duration``, faults at the paper's rates, ~8 KB of JSON per cycle), (b) the
paper's five-scenario sim run (``--scenario all --cycles 100 --seed 42``), (c) as many cycles
of typical-size records (3-5 KB, ``trace_runtime.testing.synthetic_cycle`` with a sensor
reading each). On the same records, in one run:

- raw: the canonical JSON of every message (layers, seals, checkpoints, sensor readings);
- hot: the segment files the logger wrote (zstd chunks, one per cycle);
- mcap: the same messages, channels and schemas through ``mcap.writer.Writer`` defaults;
- zstd-19: every message's bytes concatenated into one stream, zstd level 19;
- warm (default policy, lossy) and cold (from hot, lossless): ``trace_runtime.tiers.compact``.

Timings are medians of ``--repeats``. cpu = cycles per CPU-second (this process and its
workers), steadier than wall time on a shared machine. The anchor, measured in the same run,
is the JSON floor: ``orjson.loads`` + ``orjson.dumps`` of every message once (what any
re-encoding of JSON records in Python must at least do to read and to check them).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import random
import shutil
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson
import zstandard
from mcap.writer import Writer

from sim import RunConfig, run
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.schemas import SENSOR_SCHEMA_NAME, schema_bytes, schema_name
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tiers import ColdOptions, compact

FLEET_ROBOTS = 100_000
FLEET_HZ = 10
FLEET_DAYS = 183
FLEET_CYCLES = FLEET_ROBOTS * FLEET_HZ * 86_400 * FLEET_DAYS


def build_synthetic(root: Path, cycles: int) -> None:
    """Typical-size records (3-5 KB, DESIGN.md) from trace_runtime.testing.synthetic_cycle."""
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    with AuditLogger(root, robot_id="synthetic", period_s=0.1, config=config) as logger:
        for i in range(cycles):
            with logger.cycle(i * 100_000_000) as c:
                ref = c.sensor("/sensors/lidar", {"ranges": [round(2 + i % 17 / 10, 3), 4.0]})
                p, b, a, e = synthetic_cycle(i, pedestrians=1 + i // 300 % 3)
                entities = [
                    entity.model_copy(
                        update={
                            "evidence": [
                                ev.model_copy(update={"ref": ref}) for ev in entity.evidence
                            ]
                        }
                    )
                    for entity in p.entities
                ]
                c.perception(p.model_copy(update={"entities": entities}))
                c.belief(b)
                c.action(a)
                c.execution(e)


def build_logs(base: Path, hours: float) -> dict[str, Path]:
    """The sim log roots and the synthetic one (reused when present)."""
    logs = {
        "routine": (base / f"routine-{hours:g}h", {"total_cycles": round(hours * 36_000)}),
        "five-scenario": (base / "five-scenario", {"scenario": "all", "cycles": 100}),
    }
    out = {}
    for name, (root, kwargs) in logs.items():
        marker = root / "built.txt"
        if not marker.exists():
            shutil.rmtree(root, ignore_errors=True)
            print(f"building the {name} sim log in {root} ...", flush=True)
            seed = 42 if name == "five-scenario" else 2024
            run(RunConfig(out=root, seed=seed, **kwargs))
            marker.write_text("ok")
        out[name] = root
    synthetic = base / f"synthetic-{hours:g}h"
    if not (synthetic / "built.txt").exists():
        shutil.rmtree(synthetic, ignore_errors=True)
        print(f"building the synthetic log in {synthetic} ...", flush=True)
        build_synthetic(synthetic, round(hours * 36_000))
        (synthetic / "built.txt").write_text("ok")
    out["synthetic 3-5 KB"] = synthetic
    return out


def _cpu() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timed(repeats: int, fn: Callable[[], int]) -> dict[str, float]:
    """Median cycles/s (wall and cpu) of ``fn`` (which returns the cycles it handled)."""
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), _cpu()
        n = fn()
        walls.append(n / (time.perf_counter() - wall))
        cpus.append(n / max(_cpu() - cpu, 1e-9))
    return {"wall": statistics.median(walls), "cpu": statistics.median(cpus)}


def mcap_default_bytes(root: Path) -> int:
    """Every segment rewritten through mcap.writer.Writer defaults, same channels/schemas."""
    total = 0
    for segment in open_log(root).segments:
        buf = io.BytesIO()
        writer = Writer(buf)
        writer.start("trace", "bench_tiers")
        channels: dict[str, int] = {}
        schemas: dict[str, int] = {}
        for msg in segment.iter_messages():
            if msg.topic not in channels:
                name = (
                    schema_name(msg.topic)
                    if msg.topic.startswith("/trace/")
                    else SENSOR_SCHEMA_NAME
                )
                if name not in schemas:
                    schemas[name] = writer.register_schema(
                        name, "jsonschema", schema_bytes(msg.topic)
                    )
                channels[msg.topic] = writer.register_channel(msg.topic, "json", schemas[name])
            writer.add_message(
                channels[msg.topic], msg.log_time_ns, msg.data, msg.log_time_ns, msg.sequence
            )
        writer.finish()
        total += len(buf.getvalue())
    return total


def stream_zstd19_bytes(root: Path) -> int:
    compressor = zstandard.ZstdCompressor(level=19)
    out = compressor.stream_writer(counter := _Counter(), closefd=False)
    for segment in open_log(root).segments:
        for msg in segment.iter_messages():
            out.write(msg.data)
    out.flush(zstandard.FLUSH_FRAME)
    return counter.n


class _Counter(io.RawIOBase):
    def __init__(self) -> None:
        self.n = 0

    def writable(self) -> bool:
        return True

    def write(self, b: Any) -> int:
        self.n += len(b)
        return len(b)


def files_bytes(root: Path, tier: str) -> int:
    return sum(p.stat().st_size for p in (root / tier).glob("*.mcap"))


def json_floor(root: Path) -> int:
    """Anchor: parse and re-serialise every message once; returns sealed cycles."""
    cycles = 0
    for segment in open_log(root).segments:
        for msg in segment.iter_messages():
            with contextlib.suppress(orjson.JSONDecodeError):
                orjson.dumps(orjson.loads(msg.data))
            cycles += msg.topic == "/trace/seal"
    return cycles


def seek_medians_ms(hot: Any, cold: Any, times: list[int], hot_label: str) -> dict[str, float]:
    """Median ms of ``cycle_at`` at ``times``: hot and cold as a first ask (caches cleared
    before each), and cold asked again; checks that both tiers give the same cycles."""
    seeks = {}
    for label, opened, forget in (
        (hot_label, hot, True),
        ("cold, first ask", cold, True),
        ("cold, asked again", cold, False),
    ):
        samples = []
        for t_ns in times:
            if forget:
                opened.clear_caches()
            else:
                opened.cycle_at(t_ns)
            started = time.perf_counter()
            opened.cycle_at(t_ns)
            samples.append(time.perf_counter() - started)
        seeks[label] = statistics.median(samples) * 1e3
    assert all(hot.cycle_at(t) == cold.cycle_at(t) for t in times[:10])
    return seeks


def bench_log(name: str, root: Path, work: Path, repeats: int, jobs: int) -> dict[str, Any]:
    log = open_log(root)
    cycles = sum(1 for c in log.iter_cycles() if c.sealed)
    raw = sum(len(m.data) for s in log.segments for m in s.iter_messages())
    print(f"\n[{name}] {root}: {cycles} sealed cycles in {len(log.segments)} segment(s)")

    def copy(tag: str) -> Path:
        target = work / f"{name}-{tag}"
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(root, target, ignore=shutil.ignore_patterns("truth"))
        return target

    def compaction(tier: str, **kwargs: Any) -> Callable[[], int]:
        def go() -> int:
            target = copy(tier)
            report = compact(target, tier, older_than_ns=0, retention_ns=None, **kwargs)
            assert not report.failed, report.failed
            return report.cycles

        return go

    results: dict[str, Any] = {"cycles": cycles, "segments": len(log.segments)}
    sizes = {
        "raw JSON": raw,
        "hot (as logged)": files_bytes(root, "hot"),
        "MCAP default zstd": mcap_default_bytes(root),
    }
    print("  whole-stream zstd -19 ...", flush=True)
    sizes["whole-stream zstd -19"] = stream_zstd19_bytes(root)

    speed: dict[str, dict[str, float]] = {}
    speed["anchor: orjson loads+dumps"] = timed(repeats, lambda: json_floor(root))
    speed["compact cold, 1 process"] = timed(repeats, compaction("cold"))
    cold_root = work / f"{name}-cold"
    sizes["cold (lossless)"] = files_bytes(cold_root, "cold")
    if jobs > 1 and len(log.segments) > 1:  # workers take whole segments
        speed[f"compact cold, {jobs} workers"] = timed(
            repeats, compaction("cold", cold=ColdOptions(jobs=jobs))
        )
    speed["compact warm"] = timed(repeats, compaction("warm"))
    warm_root = work / f"{name}-warm"
    sizes["warm (lossy)"] = files_bytes(warm_root, "warm")
    full = sum(
        int(s.metadata["trace.tier"].get("full_cycles", 0)) for s in open_log(warm_root).segments
    )
    compact(warm_root, "cold", older_than_ns=0, retention_ns=None)
    sizes["cold of warm"] = files_bytes(warm_root, "cold")
    compacted = open_log(cold_root)

    def read_all(opened: Any) -> Callable[[], int]:
        def go() -> int:
            opened.clear_caches()  # no help from blocks decoded before
            return sum(1 for _ in opened.iter_cycles())

        return go

    speed["read all cycles, hot"] = timed(repeats, read_all(log))
    speed["read all cycles, cold"] = timed(repeats, read_all(compacted))
    rng = random.Random(5)
    times = [rng.randrange(log.start_ns, log.end_ns) for _ in range(40)]
    seeks = seek_medians_ms(log, compacted, times, hot_label="hot")

    per_cycle = {k: v / cycles for k, v in sizes.items()}
    results.update(
        bytes=sizes,
        bytes_per_cycle=per_cycle,
        speed=speed,
        seek_ms=seeks,
        warm_full_cycles=full,
    )
    _print_log(results)
    return results


def _print_log(r: dict[str, Any]) -> None:
    per = r["bytes_per_cycle"]
    mcap, z19, cold = per["MCAP default zstd"], per["whole-stream zstd -19"], per["cold (lossless)"]
    print(f"  {'form':<24}{'B/cycle':>10}{'x cold':>9}")
    for form, value in per.items():
        print(f"  {form:<24}{value:>10,.1f}{value / cold:>9.1f}")
    print(
        f"  cold / MCAP default = {cold / mcap:.3f} (budget <= 0.5);"
        f" cold / zstd-19 = {cold / z19:.3f} (budget <= 0.8)"
    )
    print(f"  warm keeps {r['warm_full_cycles']} of {r['cycles']} cycles in full")
    anchor = r["speed"]["anchor: orjson loads+dumps"]["cpu"]
    for label, rate in r["speed"].items():
        print(
            f"  {label:<30} wall {rate['wall']:>9,.0f}/s  cpu {rate['cpu']:>9,.0f}/s"
            f"  ({rate['cpu'] / anchor:.2f}x anchor)"
        )
    print(
        "  seek (cycle_at, median ms): "
        + ", ".join(f"{k} {v:.2f}" for k, v in r["seek_ms"].items())
    )


def fleet(per_cycle: dict[str, float]) -> dict[str, float]:
    """Petabytes for 100,000 robots at 10 Hz for 183 days, per storage form."""
    return {form: b * FLEET_CYCLES / 1e15 for form, b in per_cycle.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=1.0, help="routine run length (default 1)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=2, help="workers for the parallel run")
    parser.add_argument("--log", type=Path, default=Path("/tmp/trace-bench-tiers"))
    parser.add_argument("--json", type=Path, default=None, help="also write results here")
    args = parser.parse_args()

    logs = build_logs(args.log, args.hours)
    work = args.log / "work"
    work.mkdir(parents=True, exist_ok=True)
    print(f"{os.cpu_count()} CPUs; medians of {args.repeats}; load {os.getloadavg()}")
    results = {
        name: bench_log(name, root, work, args.repeats, args.jobs) for name, root in logs.items()
    }

    routine = results["routine"]
    projection = fleet(routine["bytes_per_cycle"])
    print(
        f"\nfleet projection ({FLEET_ROBOTS:,} robots, {FLEET_HZ} Hz, {FLEET_DAYS} days ="
        f" {FLEET_CYCLES:.3g} cycles) at the routine run's bytes per cycle:"
    )
    for form, pb in projection.items():
        print(f"  {form:<24}{pb:>9.2f} PB")
    print("\ncompaction speed against its budget: bench/bench_compaction.py")
    if args.json:
        args.json.write_text(
            orjson.dumps(
                {"results": results, "fleet_pb": projection, "fleet_cycles": FLEET_CYCLES},
                option=orjson.OPT_INDENT_2,
            ).decode()
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
