"""Cold compaction benchmark: whole processes against a bare rewrite of the same log.

    .venv/bin/python bench/bench_compaction.py [--hours 2] [--repeats 3] [--log DIR]
                                               [--json results.json]

Budgets (DESIGN.md and the [perf] issue): cold compaction >= 0.5x a bare read + parse +
dump + zstd-3 rewrite of the same log (whole process); 2 workers >= 1.7x one on a
multi-segment root; cold first seek <= 10 ms; cold bytes per cycle no worse than before
(~175-185 B on a routine sim hour), lossless.

The log is a routine sim run (``--hours`` of 10 Hz cycles, seed 2024) in a log root, which
the logger rotates into one segment per simulated hour; it is built once under ``--log``
and kept, so repeated runs measure the same bytes. Every timed variant runs as a whole
process (interpreter start, imports, output), in rounds whose order rotates, so a load
change on the shared machine hits all alike:

1. anchor: the ``mcap`` library's reader over every segment file, ``orjson.loads`` and
   ``orjson.dumps`` of every message, the bytes written through one zstd level-3 stream
   per segment to a file beside it (read + parse + dump + zstd-3 rewrite);
2. ``compact(root, "cold")`` in one process (the library call ``trace-audit compact``
   makes), on a fresh copy of the root (the copy is not timed);
3. the same with ``ColdOptions(jobs=2)``: segments spread over two worker processes.

Reported: medians of wall and CPU seconds (the process and its children), cycles/s, the
ratios compaction / anchor (CPU, and wall) and 2 workers / 1 (wall), with the load average.
Then, on the compacted root: bytes per sealed cycle beside the hot files and MCAP default
zstd chunks; reading every cycle; and ``cycle_at`` at 40 random times, hot and cold, each
a first ask (caches cleared) and cold asked again (median ms); and a first cold ask in a
new process (nothing decoded or compiled yet), median of 9 processes.

``--paired`` measures, instead, the codec's fast paths against the slow paths they avoid,
in one process, alternating block by block over ``--blocks`` blocks of the first segment
(the only fast/slow figure that held still on a busy shared machine): the check decode
with digest references taken from the input's digests or hashed again, and compaction's
pipeline check on the source block's objects or on the decoded copies; encoding a block,
for scale.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import random
import resource
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import orjson
from bench_tiers import mcap_default_bytes, seek_medians_ms

from sim import RunConfig, run
from trace_runtime import open_log
from trace_runtime.reading.reader import open_segment
from trace_runtime.records import TOPIC_SEAL
from trace_runtime.tier_formats import cold as cold_codec
from trace_runtime.tier_formats.cold import ColdAssembler

REPO = Path(__file__).resolve().parent.parent

ANCHOR = """
import sys
from pathlib import Path

import orjson
import zstandard
from mcap.reader import make_reader

root, out = Path(sys.argv[1]), Path(sys.argv[2])
out.mkdir(parents=True, exist_ok=True)
cycles = 0
for path in sorted(root.rglob("*.mcap")):
    with open(path, "rb") as f, open(out / (path.name + ".zst"), "wb") as o:
        writer = zstandard.ZstdCompressor(level=3).stream_writer(o)
        for _schema, channel, message in make_reader(f).iter_messages():
            writer.write(orjson.dumps(orjson.loads(message.data)))
            cycles += channel.topic == "/trace/seal"
        writer.flush(zstandard.FLUSH_FRAME)
print(cycles)
"""

COMPACT = """
import sys
from trace_runtime.tiers import ColdOptions, compact

def main():
    report = compact(sys.argv[1], "cold", older_than_ns=0, retention_ns=None,
                     cold=ColdOptions(jobs=int(sys.argv[2])))
    assert not report.failed, report.failed
    print(report.cycles)

if __name__ == "__main__":
    main()
"""


def build_log(root: Path, hours: float) -> int:
    """A routine sim log root of ``hours`` (one segment per simulated hour); reused."""
    marker = root / "cycles.txt"
    if marker.exists():
        return int(marker.read_text())
    shutil.rmtree(root, ignore_errors=True)
    cycles = round(hours * 36_000)
    print(f"building a {hours:g} h sim log ({cycles} cycles) in {root} ...", flush=True)
    result = run(RunConfig(out=root, total_cycles=cycles, seed=2024))
    shutil.rmtree(root / "truth", ignore_errors=True)  # ground truth is not part of the log
    marker.write_text(str(result.written))
    return result.written


@dataclass
class Variant:
    label: str
    code: str
    walls: list[float] = field(default_factory=list)
    cpus: list[float] = field(default_factory=list)

    def wall(self) -> float:
        return statistics.median(self.walls)

    def cpu(self) -> float:
        return statistics.median(self.cpus)


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def fresh_copy(source: Path, target: Path) -> Path:
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("cycles.txt", "truth"))
    return target


def measure(variant: Variant, argv: list[str]) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cpu, wall = _children_cpu(), time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, env=env, cwd=REPO)
    variant.walls.append(time.perf_counter() - wall)
    variant.cpus.append(_children_cpu() - cpu)


def seeks_ms(hot: Any, cold: Any, rng: random.Random) -> dict[str, float]:
    """Median ms of ``cycle_at`` at random times: a first ask (caches cleared), and asked again."""
    times = [rng.randrange(hot.start_ns, hot.end_ns) for _ in range(40)]
    out = seek_medians_ms(hot, cold, times, hot_label="hot, first ask")
    # the same first asks answered by decoding the whole block (no partial decode),
    # alternating with the partial ones so a busy spell hits both: a paired ratio
    whole: list[float] = []
    partial: list[float] = []
    for t_ns in times:
        for kind in (whole, partial):
            with _whole_block_seeks(kind is whole):
                cold.clear_caches()
                started = time.perf_counter()
                cold.cycle_at(t_ns)
                kind.append(time.perf_counter() - started)
    out["cold, first ask, whole-block decode"] = statistics.median(whole) * 1e3
    out["cold, whole / partial (paired)"] = statistics.median(
        w / p for w, p in zip(whole, partial, strict=True)
    )
    return out


@contextlib.contextmanager
def _whole_block_seeks(on: bool) -> Iterator[None]:
    """Without ``ColdAssembler.cycle_at`` the reader assembles the whole block and filters."""
    saved = ColdAssembler.cycle_at
    if on:
        ColdAssembler.cycle_at = None  # type: ignore[assignment,method-assign]
    try:
        yield
    finally:
        ColdAssembler.cycle_at = saved  # type: ignore[method-assign]


FIRST_SEEK = """
import random, sys, time
from trace_runtime import open_log

log = open_log(sys.argv[1])
log.cycle_at(log.start_ns)  # the reader itself warm (files, summaries), on another block
t_ns = random.Random(int(sys.argv[2])).randrange(log.start_ns, log.end_ns)
log.clear_caches()
started = time.perf_counter()
log.cycle_at(t_ns)
print((time.perf_counter() - started) * 1e3)
"""


def fresh_process_seeks_ms(root: Path, runs: int = 9) -> float:
    """Median ms of a first cold ``cycle_at`` in a new process (nothing decoded or
    compiled yet: what ``trace-audit explain`` on a cold log pays), over ``runs`` times."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    samples = []
    for seed in range(runs):
        out = subprocess.run(
            [sys.executable, "-c", FIRST_SEEK, str(root), str(seed)],
            check=True,
            capture_output=True,
            text=True,
            env=env,
        )
        samples.append(float(out.stdout))
    return statistics.median(samples)


def read_all(opened: Any) -> float:
    """Cycles per second reading every cycle (caches cleared first)."""
    opened.clear_caches()
    started = time.perf_counter()
    n = sum(1 for _ in opened.iter_cycles())
    return n / (time.perf_counter() - started)


def paired_fast_paths(segment: Path, blocks: int, passes: int = 5) -> dict[str, float]:
    """Microseconds per cycle of each fast path and the slow one it replaced, alternating
    block by block (the order flips every block and pass), and the median paired ratios."""
    opened = open_segment(segment)
    source = cold_codec.iter_blocks(opened.iter_messages(), cold_codec.DEFAULT_BLOCK_CYCLES)
    encoder = cold_codec.BlockEncoder()
    items = []
    for block in itertools.islice(source, blocks):
        kept, plain, positions = cold_codec.split_plain(block)
        data, decoded = encoder.encode_checked(kept, opened.session.tier, positions)
        digests = list(encoder._last_digests)
        items.append((block, kept, plain, positions, data, digests, decoded))
    cycles = sum(sum(m.topic == TOPIC_SEAL for m in item[0]) for item in items)

    def encode(fast: bool, item: tuple[Any, ...]) -> bytes:  # the same either way: for scale
        return encoder._encode(item[1], opened.session.tier, item[3], verbatim=False)

    checker = cold_codec.BlockCache(0)

    def check(fast: bool, item: tuple[Any, ...]) -> Any:
        data, digests = item[4], item[5]
        return checker.decode_checked(data, digests) if fast else checker.decode(data)

    def compare(fast: bool, item: tuple[Any, ...]) -> bool:
        block, kept, plain, positions, _data, _digests, decoded = item
        if fast:
            return bool(list(cold_codec.merge_plain(kept, plain, positions)) == block)
        return bool(list(cold_codec.merge_plain(decoded.messages, plain, decoded.plain)) == block)

    stages: dict[str, Callable[[bool, tuple[Any, ...]], Any]] = {
        "encode": encode,
        "check decode": check,
        "compare with source": compare,
    }
    spent = {(name, fast): 0.0 for name in stages for fast in (False, True)}
    ratios: dict[str, list[float]] = {name: [] for name in stages}
    with cold_codec.gc_paused():
        for number in range(passes):
            for at, item in enumerate(items):
                for name, stage in stages.items():
                    took = {}
                    for fast in (True, False) if (at + number) % 2 else (False, True):
                        started = time.thread_time()
                        stage(fast, item)
                        took[fast] = time.thread_time() - started
                    spent[name, False] += took[False]
                    spent[name, True] += took[True]
                    ratios[name].append(took[False] / max(took[True], 1e-9))
    results: dict[str, float] = {}
    for name in stages:
        for fast, label in ((False, "before"), (True, "after")):
            results[f"{name}, {label}, us/cycle"] = spent[name, fast] / passes / cycles * 1e6
        results[f"{name}, before / after (paired)"] = statistics.median(ratios[name])
    return results


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=2.0, help="simulated hours (default 2)")
    parser.add_argument("--repeats", type=int, default=3, help="rounds (medians are taken)")
    parser.add_argument("--log", type=Path, default=Path("/tmp/trace-bench-compaction"))
    parser.add_argument("--json", type=Path, default=None, help="also write results here")
    parser.add_argument(
        "--paired", action="store_true", help="only the fast paths against the slow ones"
    )
    parser.add_argument("--blocks", type=int, default=24, help="blocks for --paired")
    args = parser.parse_args()

    source = args.log / f"{args.hours:g}h"
    cycles = build_log(source, args.hours)
    if args.paired:
        paired = paired_fast_paths(sorted(source.rglob("*.mcap"))[0], args.blocks)
        for label, value in paired.items():
            print(f"{label:<44} {value:>8.3f}")
        print(f"load average {os.getloadavg()[0]:.2f} on {len(os.sched_getaffinity(0))} CPUs")
        if args.json:
            args.json.write_text(orjson.dumps(paired, option=orjson.OPT_INDENT_2).decode())
        return 0
    work = args.log / "work"
    segments = sorted(source.rglob("*.mcap"))
    py = sys.executable
    anchor = Variant("anchor: mcap read+parse+dump+zstd-3", ANCHOR)
    one = Variant("compact cold, 1 process", COMPACT)
    two = Variant("compact cold, 2 workers", COMPACT)
    variants = [anchor, one, two]
    print(
        f"log: {source} ({cycles} cycles, {len(segments)} segments, "
        f"{sum(p.stat().st_size for p in segments) / 1e6:.1f} MB); "
        f"{len(os.sched_getaffinity(0))} CPUs; {args.repeats} rounds, whole processes",
        flush=True,
    )
    loads = []
    for round_no in range(args.repeats):
        for variant in variants[round_no % 3 :] + variants[: round_no % 3]:
            if variant is anchor:
                argv = [py, "-c", ANCHOR, str(source), str(work / "anchor-out")]
            else:
                target = fresh_copy(source, work / "cold")
                argv = [py, "-c", COMPACT, str(target), "2" if variant is two else "1"]
            measure(variant, argv)
        loads.append(os.getloadavg()[0])
        print(
            f"  round {round_no + 1}: "
            + ", ".join(f"{v.label.split(':')[0]} {v.walls[-1]:.1f}s" for v in variants)
            + f" (load {loads[-1]:.2f})",
            flush=True,
        )

    print(f"\n{'':<40} {'wall s':>7} {'cpu s':>7} {'cycles/s wall':>14} {'cycles/s cpu':>13}")
    for v in variants:
        print(
            f"{v.label:<40} {v.wall():>7.2f} {v.cpu():>7.2f}"
            f" {cycles / v.wall():>14,.0f} {cycles / v.cpu():>13,.0f}"
        )
    ratio_cpu, ratio_wall = anchor.cpu() / one.cpu(), anchor.wall() / one.wall()
    scaling = one.wall() / two.wall()
    load = statistics.median(loads)
    print(
        f"\ncompaction / anchor, 1 process: cpu {ratio_cpu:.2f}x, wall {ratio_wall:.2f}x"
        "   (budget >= 0.5x)"
    )
    print(
        f"2 workers / 1, wall:            {scaling:.2f}x over {len(segments)} segments"
        f"   (budget >= 1.7x; load average {load:.2f} on {len(os.sched_getaffinity(0))} CPUs)"
    )
    print(f"2 workers, cpu:                 {two.cpu() / one.cpu():.2f}x the CPU of one process")

    # sizes, reads and seeks on the compacted root (a last 1-process run, untimed)
    cold_root = fresh_copy(source, work / "cold")
    subprocess.run(
        [py, "-c", COMPACT, str(cold_root), "1"],
        check=True,
        stdout=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    hot, cold = open_log(source), open_log(cold_root)
    sizes = {
        "hot (as logged)": sum(p.stat().st_size for p in segments),
        "MCAP default zstd": mcap_default_bytes(source),
        "cold": sum(p.stat().st_size for p in (cold_root / "cold").glob("*.mcap")),
    }
    per_cycle = {k: v / cycles for k, v in sizes.items()}
    print(f"\n{'form':<24}{'B/cycle':>10}")
    for form, value in per_cycle.items():
        print(f"{form:<24}{value:>10,.1f}")
    print(f"cold / MCAP default = {per_cycle['cold'] / per_cycle['MCAP default zstd']:.3f}")
    reads = {"hot": read_all(hot), "cold": read_all(cold)}
    print(f"read every cycle: hot {reads['hot']:,.0f}/s, cold {reads['cold']:,.0f}/s")
    seeks = seeks_ms(hot, cold, random.Random(5))
    seeks["cold, first ask in a new process"] = fresh_process_seeks_ms(cold_root)
    print(
        "cycle_at, median ms: "
        + ", ".join(f"{k} {v:.2f}" for k, v in seeks.items())
        + "   (budget: cold first ask <= 10 ms)"
    )
    if args.json:
        results = {
            "cycles": cycles,
            "segments": len(segments),
            "variants": {v.label: {"walls": v.walls, "cpus": v.cpus} for v in variants},
            "ratio_cpu": ratio_cpu,
            "ratio_wall": ratio_wall,
            "workers_scaling": scaling,
            "load": loads,
            "bytes_per_cycle": per_cycle,
            "read_cycles_per_s": reads,
            "seek_ms": seeks,
        }
        args.json.write_text(orjson.dumps(results, option=orjson.OPT_INDENT_2).decode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
