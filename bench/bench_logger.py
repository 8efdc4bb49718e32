"""Logger benchmarks (issue: foundation), each against its anchor measured in the same run.

    .venv/bin/python bench/bench_logger.py [--quick]

1. control-thread cost per cycle (p50, p99) for a typical 3-5 KB cycle, paced like a control
   loop; anchor: writing the same cycle synchronously with the plain `mcap` Writer + orjson.
2. sustained throughput of one writer (cycles/s), with built records and with the plain
   dicts a robot may hand over instead (validation included); anchor: plain `mcap` Writer +
   orjson of the same records (``model_dump`` + orjson for built ones, orjson of the dict).
3. cycles lost on kill -9 at a random moment, over N runs; anchor: `mcap` Writer defaults.
4. bytes per cycle in the hot tier (paced: a chunk per cycle; and batched when catching up).

Medians and ratios, never one absolute time: this machine is shared and noisy.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import orjson
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.encoding.codec import encode_layer
from trace_runtime.records import LAYER_TOPICS
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 100_000_000


def _cycles(n: int) -> list[tuple]:
    return [synthetic_cycle(i) for i in range(n)]


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# --- 1. control-thread cost ----------------------------------------------------------------


def control_cost_ours(records: list[tuple], path: Path, pace_s: float) -> list[float]:
    costs = []
    with AuditLogger(path, robot_id="bench", config=LoggerConfig(fsync_interval_s=1.0)) as log:
        for i, (p, b, a, e) in enumerate(records):
            start = time.perf_counter_ns()
            with log.cycle(i * PERIOD_NS) as c:
                c.sensor("/sensors/lidar", {"ranges": [1.5, 1.6, 1.7], "cluster": i})
                c.perception(p)
                c.belief(b)
                c.action(a)
                c.execution(e)
            costs.append((time.perf_counter_ns() - start) / 1000)
            time.sleep(pace_s)
    return costs


def control_cost_anchor(records: list[tuple], path: Path, pace_s: float) -> list[float]:
    """The same cycle written synchronously by the plain mcap Writer with orjson payloads."""
    costs = []
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="trace")
        schema = writer.register_schema("trace", "jsonschema", b"{}")
        channels = {t: writer.register_channel(t, "json", schema) for t in LAYER_TOPICS}
        sensor = writer.register_channel("/sensors/lidar", "json", schema)
        for i, layers in enumerate(records):
            start = time.perf_counter_ns()
            t = i * PERIOD_NS
            writer.add_message(sensor, t, orjson.dumps({"ranges": [1.5, 1.6, 1.7]}), t)
            for topic, record in zip(LAYER_TOPICS, layers, strict=True):
                writer.add_message(channels[topic], t, orjson.dumps(record.model_dump()), t)
            costs.append((time.perf_counter_ns() - start) / 1000)
            time.sleep(pace_s)
        writer.finish()
    return costs


# --- 2. throughput ---------------------------------------------------------------------------


def throughput_ours(records: list[tuple], path: Path, *, threaded: bool = True) -> float:
    config = LoggerConfig(
        threaded=threaded, when_full="block", queue_cycles=4096, fsync_interval_s=None
    )
    start = time.perf_counter()
    with AuditLogger(path, robot_id="bench", config=config) as log:
        for i, (p, b, a, e) in enumerate(records):
            log.log_cycle(i * PERIOD_NS, perception=p, belief=b, action=a, execution=e)
    return len(records) / (time.perf_counter() - start)


def throughput_anchor(records: list[tuple], path: Path) -> float:
    start = time.perf_counter()
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="trace")
        schema = writer.register_schema("trace", "jsonschema", b"{}")
        channels = [writer.register_channel(t, "json", schema) for t in LAYER_TOPICS]
        for i, layers in enumerate(records):
            t = i * PERIOD_NS
            for channel, record in zip(channels, layers, strict=True):
                data = record if isinstance(record, dict) else record.model_dump()
                writer.add_message(channel, t, orjson.dumps(data), t)
        writer.finish()
    return len(records) / (time.perf_counter() - start)


def throughput(records: list[tuple], work: Path, tag: str, runs: int = 3) -> dict[str, float]:
    """Median cycles/s of ours (threaded, and synchronous) and of the anchor, interleaved."""
    got: dict[str, list[float]] = {"ours": [], "ours sync": [], "anchor": []}
    for k in range(runs):
        got["ours"].append(throughput_ours(records, work / f"tp-{tag}-{k}.mcap"))
        got["ours sync"].append(
            throughput_ours(records, work / f"tps-{tag}-{k}.mcap", threaded=False)
        )
        got["anchor"].append(throughput_anchor(records, work / f"tpa-{tag}-{k}.mcap"))
    return {name: statistics.median(values) for name, values in got.items()}


# --- 3. kill -9 ------------------------------------------------------------------------------

_CHILD = textwrap.dedent(
    """
    import sys, time, orjson
    from trace_runtime.testing import synthetic_cycle
    from trace_runtime.records import LAYER_TOPICS
    kind, out = sys.argv[1], sys.argv[2]
    period = 0.01
    if kind == "ours":
        from trace_runtime import AuditLogger, LoggerConfig
        log = AuditLogger(out, robot_id="k", config=LoggerConfig(fsync_interval_s=None))
        def write(i, layers):
            p, b, a, e = layers
            log.log_cycle(i * 10_000_000, perception=p, belief=b, action=a, execution=e)
    else:
        from mcap.writer import Writer
        f = open(out, "wb")
        w = Writer(f)
        w.start(profile="trace")
        s = w.register_schema("trace", "jsonschema", b"{}")
        ch = [w.register_channel(t, "json", s) for t in LAYER_TOPICS]
        def write(i, layers):
            for c, r in zip(ch, layers):
                w.add_message(c, i * 10_000_000, orjson.dumps(r.model_dump()), i * 10_000_000,
                              sequence=i)
    i = 0
    while True:
        write(i, synthetic_cycle(i))
        print(i, flush=True)
        i += 1
        time.sleep(period)
    """
)


def _last_cycle_on_disk(kind: str, path: Path) -> int:
    if kind == "ours":
        cycles = list(open_log(path).iter_cycles())
        return cycles[-1].cycle if cycles else -1
    last = -1
    try:
        with path.open("rb") as f:
            for record in StreamReader(f, skip_magic=False).records:
                for msg in getattr(record, "messages", []) or []:
                    last = max(last, msg.sequence)
                if type(record).__name__ == "Message":
                    last = max(last, record.sequence)  # type: ignore[attr-defined]
    except Exception:  # a truncated file ends the scan; what was read before counts
        pass
    return last


def kill_runs(kind: str, runs: int, workdir: Path) -> list[int]:
    """Run a 100 Hz robot, SIGKILL it at a random moment; return cycles lost per run."""
    lost = []
    for run in range(runs):
        out = workdir / f"{kind}-{run}.mcap"
        with subprocess.Popen(
            [sys.executable, "-c", _CHILD, kind, str(out)], stdout=subprocess.PIPE, text=True
        ) as proc:
            assert proc.stdout is not None
            stop_after = random.uniform(0.3, 2.0)
            start = time.monotonic()
            committed = -1
            while time.monotonic() - start < stop_after:
                line = proc.stdout.readline()
                if not line:
                    break
                committed = int(line)
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
            for line in proc.stdout.read().splitlines():
                committed = int(line)
        lost.append(committed - _last_cycle_on_disk(kind, out))
    return lost


# --- main ------------------------------------------------------------------------------------


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer cycles and kill runs")
    args = parser.parse_args()
    # Every run writes ~300 MB of logs: they go when the run ends, however it ends.
    with tempfile.TemporaryDirectory(prefix="bench-logger-") as work:
        run(Path(work), quick=args.quick)


def run(work: Path, *, quick: bool) -> None:
    n_paced = 600 if quick else 2000
    n_fast = 5000 if quick else 20000
    kills = 10 if quick else 20
    records = _cycles(max(n_paced, 2000))
    size = statistics.median(
        sum(len(encode_layer(i, i, r)) for r in layers) for i, layers in enumerate(records[:200])
    )
    print(f"record size: median {size:.0f} B of canonical JSON per cycle (4 layers)")

    pace = 0.002  # a 500 Hz loop: the writer keeps up, as it must on a real robot
    ours = control_cost_ours(records[:n_paced], work / "paced.mcap", pace)
    anchor = control_cost_anchor(records[:n_paced], work / "anchor-paced.mcap", pace)
    print(f"\n1. control-thread cost per cycle (us), paced at 500 Hz, {n_paced} cycles")
    print(
        f"   ours           p50 {_percentile(ours, 0.5):7.1f}  p99 {_percentile(ours, 0.99):7.1f}"
        f"  mean {statistics.fmean(ours):7.1f}"
    )
    print(
        f"   mcap+orjson    p50 {_percentile(anchor, 0.5):7.1f}  "
        f"p99 {_percentile(anchor, 0.99):7.1f}  mean {statistics.fmean(anchor):7.1f}"
    )
    print("   paper          mean   120.0 (reported)")
    print(f"   ratio ours/anchor p50 {_percentile(ours, 0.5) / _percentile(anchor, 0.5):.2f}")
    hot = (work / "paced.mcap").stat().st_size / n_paced
    print(f"\n4. hot tier: {hot:.0f} B/cycle paced (one chunk per cycle)")

    fast = records * (n_fast // len(records) + 1)
    fast = fast[:n_fast]
    dicts = [tuple(r.model_dump(by_alias=True) for r in layers) for layers in fast]
    built_tp = throughput(fast, work, "built")
    batched = (work / "tp-built-0.mcap").stat().st_size / n_fast
    print(f"   hot tier: {batched:.0f} B/cycle when the writer batches (catching up)")
    dict_tp = throughput(dicts, work, "dicts")
    print(f"\n2. throughput, {n_fast} cycles, median of 3 interleaved runs (cycles/s)")
    for label, tp in (("built records", built_tp), ("plain dicts, validated", dict_tp)):
        print(
            f"   {label:23s} ours {tp['ours']:7.0f}  (sync {tp['ours sync']:7.0f})  "
            f"mcap+orjson {tp['anchor']:7.0f}  ratio {tp['ours'] / tp['anchor']:.2f} "
            f"(sync {tp['ours sync'] / tp['anchor']:.2f})"
        )

    lost_ours = kill_runs("ours", kills, work)
    lost_anchor = kill_runs("anchor", kills, work)
    print(f"\n3. cycles lost on kill -9, {kills} runs at 100 Hz")
    print(
        f"   ours        max {max(lost_ours)}  median {statistics.median(lost_ours)}  "
        f"runs {lost_ours}"
    )
    print(f"   mcap defaults max {max(lost_anchor)}  median {statistics.median(lost_anchor)}")


if __name__ == "__main__":
    main()
