"""Compaction under kill -9: how many cycles are lost when a compaction is killed anywhere?

A log root of hot segments is written with ``AuditLogger``; each run copies it, starts
``compact --tier cold`` in a child process and SIGKILLs it at a random moment (after a random
number of blocks plus up to 20 ms, or right after a random rename / fsync / chunk write,
which includes the moment between a replacement's rename and its source's removal). Then one
more compaction runs in this process, and the run counts, against the original log:

- cycles lost (in the original, not read by ``open_log`` afterwards; goal 0),
- cycles duplicated (read more than once; goal 0),
- segments left in two tiers or half-written, runs that failed or held copies,
- runs where ``verify`` is not clean.

    .venv/bin/python bench/bench_compaction_faults.py --runs 50 --seed 1
"""

from __future__ import annotations

import argparse
import collections
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from trace_audit.verify import verify_log  # noqa: E402
from trace_runtime import AuditLogger, LoggerConfig, open_log  # noqa: E402
from trace_runtime.testing import synthetic_cycle  # noqa: E402
from trace_runtime.tiers import ColdOptions, compact  # noqa: E402

T0_NS = 1_000_000_000_000
PERIOD_NS = 100_000_000
BLOCK_CYCLES = 32

_CHILD = """
import os, signal, sys
sys.path.insert(0, {repo!r})
from trace_runtime.tiers import ColdOptions, compact
from trace_runtime.tiers import replace as module

target, nth = {hook!r}
calls = [0]

def kill_after(owner, name):
    real = getattr(owner, name)
    def wrapped(*args, **kwargs):
        result = real(*args, **kwargs)
        calls[0] += 1
        if calls[0] == nth:
            os.kill(os.getpid(), signal.SIGKILL)
        return result
    setattr(owner, name, wrapped)

if target == "replace":
    kill_after(module.os, "replace")
elif target == "fsync":
    kill_after(os, "fsync")
elif target == "unlink":
    from pathlib import Path
    real_unlink = Path.unlink
    def unlink(self, *args, **kwargs):
        calls[0] += 1
        if calls[0] == nth:
            os.kill(os.getpid(), signal.SIGKILL)  # before the source goes
        return real_unlink(self, *args, **kwargs)
    Path.unlink = unlink
elif target == "write_batch":
    from trace_runtime.logger.segment_writer import SegmentWriter
    kill_after(SegmentWriter, "write_batch")
print("start", flush=True)
compact({root!r}, "cold", older_than_ns=0, cold=ColdOptions(block_cycles={block}),
        progress=lambda event: print("block", flush=True))
print("done", flush=True)
"""


def make_root(root: Path, segments: int, cycles: int) -> Path:
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    index = 0
    for _ in range(segments):
        logger = AuditLogger(root, robot_id="amr-1", period_s=0.1, config=config)
        for _ in range(cycles):
            with logger.cycle(T0_NS + index * PERIOD_NS) as c:
                c.sensor("/sensors/lidar", {"ranges": [2.0 + 0.01 * (index % 13)], "i": index})
                perception, belief, action, execution = synthetic_cycle(index)
                c.perception(perception)
                c.belief(belief)
                c.action(action)
                c.execution(execution)
            index += 1
        logger.close()
    return root


def cycle_key(cycle: Any) -> tuple[Any, ...]:
    return (cycle.cycle, cycle.t_ns, tuple(sorted(cycle.payloads.items())))


def kill_once(root: Path, rng: random.Random, blocks: int) -> str:
    if rng.random() < 0.5:
        hook: tuple[str, int] = (
            rng.choice(["replace", "fsync", "unlink", "write_batch"]),
            rng.randint(1, 8),
        )
    else:
        hook = ("none", 0)
    code = _CHILD.format(repo=str(REPO), root=str(root), hook=hook, block=BLOCK_CYCLES)
    with subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=REPO
    ) as proc:
        assert proc.stdout is not None
        proc.stdout.readline()
        where = f"{hook[0]} #{hook[1]}"
        if hook[0] == "none":
            seen = rng.randrange(0, blocks)
            for _ in range(seen):
                proc.stdout.readline()
            delay = rng.uniform(0.0, 0.02)
            time.sleep(delay)
            proc.send_signal(signal.SIGKILL)
            where = f"{seen} blocks + {delay * 1000:.1f} ms"
        proc.communicate(timeout=120)
        killed = proc.returncode == -signal.SIGKILL
    return where + ("" if killed else " (finished first)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=50)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--segments", type=int, default=4)
    parser.add_argument("--cycles", type=int, default=200)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        template = make_root(Path(tmp) / "template", args.segments, args.cycles)
        original = collections.Counter(cycle_key(c) for c in open_log(template).iter_cycles())
        names = sorted(p.name for p in (template / "hot").glob("*.mcap"))
        blocks = args.segments * -(-args.cycles // BLOCK_CYCLES)
        totals = collections.Counter[str]()
        started = time.perf_counter()
        for run in range(args.runs):
            root = Path(tmp) / f"run{run}"
            shutil.copytree(template, root)
            where = kill_once(root, rng, blocks)
            report = compact(root, "cold", older_than_ns=0, cold=ColdOptions(BLOCK_CYCLES))
            read = collections.Counter(cycle_key(c) for c in open_log(root).iter_cycles())
            lost = sum((original - read).values())
            duplicated = sum((read - original).values())
            layout = sorted(p.relative_to(root).as_posix() for p in root.glob("*/*.mcap*"))
            misplaced = layout != [f"cold/{n}" for n in names]
            clean = verify_log(root).ok
            totals["lost"] += lost
            totals["duplicated"] += duplicated
            totals["misplaced"] += misplaced
            totals["not clean"] += not clean
            totals["failed or held"] += bool(report.failed or report.held)
            totals["killed"] += "finished first" not in where
            print(
                f"run {run:2d} killed at {where:28s} lost {lost} duplicated {duplicated} "
                f"{'MISPLACED ' if misplaced else ''}verify {'clean' if clean else 'FINDINGS'}",
                flush=True,
            )
            shutil.rmtree(root)
        cycles = sum(original.values())
        print(
            f"\n{args.runs} runs ({totals['killed']} killed mid-run) on {args.segments} segments "
            f"x {args.cycles} cycles ({cycles} cycles), {time.perf_counter() - started:.0f} s:\n"
            f"  cycles lost: {totals['lost']} (goal 0)\n"
            f"  cycles duplicated: {totals['duplicated']}\n"
            f"  runs with a segment in two tiers or half-written after recovery: "
            f"{totals['misplaced']}\n"
            f"  runs failed or holding copies: {totals['failed or held']}\n"
            f"  runs where verify is not clean: {totals['not clean']}"
        )


if __name__ == "__main__":
    main()
