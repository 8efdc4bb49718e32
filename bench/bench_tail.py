"""Tail benchmark: what one poll of ``trace-audit tail --follow`` costs on a long live segment.

    .venv/bin/python bench/bench_tail.py [--cycles 20000] [--polls 21] [--repeats 3]
        [--before /tmp/old-tail]

Target (issue [look], tail): a poll reads only what the logger appended since the last one,
so its cost does not grow with the segment: on a live segment of 20,000 cycles a poll costs
a small fraction of one read of the whole segment (the anchor), where re-reading the segment
at every poll costs more than that read.

Each measurement is a fresh process of one checkout (this one; with ``--before``, also an
older checkout, e.g. ``git worktree add /tmp/old-tail <commit>``), in rounds so a load change
on the shared machine hits both alike. The process:

1. logs ``--cycles`` cycles into a new root with the real ``AuditLogger`` (unthreaded, one
   chunk a cycle, never rotating) and keeps it open: the segment is live, its lock held;
2. anchor: reads that segment once, whole, with the reader (``Segment(path).iter_cycles()``);
3. starts ``tail(root, follow=True, poll_s=0)`` and reads its first pass (the segment so far);
4. ``--polls`` times: logs one cycle whose command differs from the last, and takes the CPU
   time of the thread until tail yields that change: one poll, which finds the new chunk.
   (The thread's CPU time: what the poll computes, not the wait between polls.) The first
   is dropped: it also finishes the first pass.

Reported: medians over rounds of each checkout's median poll and of the anchor (CPU ms),
poll / anchor, and the ratio before / after.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

CHILD = """
import json, statistics, sys, time
from pathlib import Path
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.reading.reader import Segment
from trace_runtime.testing import synthetic_cycle
from trace_audit.tail import DecisionChange, tail

root, cycles, polls = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
config = LoggerConfig(threaded=False, max_segment_s=10.0**9)
log = AuditLogger(root, robot_id="r", config=config)

def write(i, command):
    p, b, a, e = synthetic_cycle(i)
    a = a.model_copy(update={"command": command})
    log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)

for i in range(cycles):
    write(i, "STOP")
path = next(root.rglob("*.mcap"))
cpu = time.thread_time()
read = sum(1 for _ in Segment(path).iter_cycles())
anchor = time.thread_time() - cpu
assert read == cycles, read
events = tail(root, follow=True, poll_s=0.0)
while not isinstance(next(events), DecisionChange):
    pass  # the segment's state, then its first change (cycle 0)
costs = []
for n in range(polls):
    i = cycles + n
    write(i, ("SLOW", "STOP")[n % 2])
    cpu = time.thread_time()
    event = next(events)
    costs.append(time.thread_time() - cpu)
    assert isinstance(event, DecisionChange) and event.cycle == i, event
events.close()
log.close()
print(json.dumps({"anchor": anchor, "poll": statistics.median(costs[1:]),
                  "bytes": path.stat().st_size}))
"""


def measure(checkout: Path, cycles: int, polls: int) -> dict[str, float]:
    """One process of ``checkout``: its anchor and median poll, in CPU seconds."""
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    with tempfile.TemporaryDirectory(prefix="bench-tail-") as tmp:
        done = subprocess.run(
            [sys.executable, "-c", CHILD, str(Path(tmp) / "root"), str(cycles), str(polls)],
            env=env,
            cwd=checkout,
            check=True,
            capture_output=True,
            text=True,
        )
    result: dict[str, float] = json.loads(done.stdout.splitlines()[-1])
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", type=int, default=20_000, help="cycles in the live segment")
    parser.add_argument("--polls", type=int, default=21, help="polls measured per process")
    parser.add_argument("--repeats", type=int, default=3, help="rounds (medians are taken)")
    parser.add_argument("--before", type=Path, help="an older checkout to compare against")
    args = parser.parse_args()
    checkouts = {"after": REPO} | ({"before": args.before} if args.before else {})
    runs: dict[str, list[dict[str, float]]] = {label: [] for label in checkouts}
    for _ in range(args.repeats):
        for label, checkout in checkouts.items():
            runs[label].append(measure(checkout, args.cycles, args.polls))
    size = runs["after"][0]["bytes"]
    print(
        f"live segment of {args.cycles} cycles ({size / 1e6:.1f} MB), {args.polls - 1} polls "
        f"a process, {args.repeats} rounds, load {os.getloadavg()[0]:.2f}"
    )
    medians: dict[str, float] = {}
    for label in ("before", "after"):
        if label not in runs:
            continue
        poll = statistics.median(r["poll"] for r in runs[label])
        anchor = statistics.median(r["anchor"] for r in runs[label])
        medians[label] = poll
        print(
            f"  {label:6s} poll {poll * 1e3:9.3f} ms cpu   anchor (one whole read) "
            f"{anchor * 1e3:8.1f} ms   poll / anchor {poll / anchor:.4f}"
        )
    if "before" in medians:
        print(f"  before / after: {medians['before'] / medians['after']:.0f}x less CPU a poll")
    return 0


if __name__ == "__main__":
    sys.exit(main())
