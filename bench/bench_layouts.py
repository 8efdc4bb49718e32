"""Benchmark: what reading a log costs in each MCAP layout, against the reference reader.

A simulator log (10 min by default) is rewritten with the reference ``mcap`` Writer in the
layouts where our reader must look elsewhere for the chunks (``tests/mcap_variants``): the
writer's own file (our chunk-table attachment), a copy whose attachment is stale (kept by a
rewriting tool, so the Chunk Index is used), no Chunk Index (a walk of the data section),
no chunks at all, no Statistics, channels only inside chunks. For each, two questions run
in this process, each the median of ``--runs``:

- ``open``: open the segment (what every command pays first, e.g. a seek for ``explain``);
- ``cycles``: open and read every cycle.

The anchor, in the same run and the same layout, is the reference reader reading every
message with its linear reader (``mcap.reader.NonSeekingReader``; its seeking reader raises
KeyError on a file whose channels are only inside chunks, so it cannot be the anchor of
every layout). Ratios above 1 mean ours is faster.

    .venv/bin/python bench/bench_layouts.py [--minutes 10] [--runs 5] [--json]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mcap.reader import NonSeekingReader

from tests.mcap_variants import Variant, rewrite
from trace_runtime import open_segment

LAYOUTS = {
    "as written (our attachment)": None,
    "stale attachment (Chunk Index)": Variant(),
    "no Chunk Index (walk)": Variant(chunk_index=False, attachments=False),
    "no chunks": Variant(chunked=False),
    "no Statistics": Variant(statistics=False),
    "channels only in chunks": Variant(repeat=False),
}


def _median(runs: int, work: Callable[[], object]) -> float:
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def _reference(path: Path) -> int:
    with path.open("rb") as f:
        return sum(1 for _ in NonSeekingReader(f).iter_messages())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=int, default=10)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
        subprocess.run(
            [
                *(sys.executable, "-m", "evaluation.cli", "run"),
                *("--duration", f"{args.minutes}m", "--seed", "1", "--out", str(base / "root")),
            ],
            check=True,
            env=env,
            capture_output=True,
        )
        source = next((base / "root" / "hot").glob("*.mcap"))
        rows = []
        for name, variant in LAYOUTS.items():
            path = source if variant is None else rewrite(source, base / "copy.mcap", variant)
            opened = _median(args.runs, lambda p=path: open_segment(p))
            cycles = _median(
                args.runs, lambda p=path: sum(1 for _ in open_segment(p).iter_cycles())
            )
            anchor = _median(args.runs, lambda p=path: _reference(p))
            n = sum(1 for _ in open_segment(path).iter_cycles())
            rows.append(
                {
                    "layout": name,
                    "cycles": n,
                    "open_ms": round(opened * 1e3, 2),
                    "cycles_s": round(cycles, 3),
                    "reference_s": round(anchor, 3),
                    "ratio": round(anchor / cycles, 2),
                }
            )
    load = os.getloadavg()[0]
    if args.json:
        print(json.dumps({"load_average": load, "rows": rows}, indent=2))
        return 0
    print(f"layout reads, {args.minutes} min sim log, median of {args.runs}; load {load:.1f}")
    print(
        f"{'layout':34} {'cycles':>7} {'open ms':>8} {'cycles s':>9} {'ref s':>7} {'ref/ours':>8}"
    )
    for r in rows:
        print(
            f"{r['layout']:34} {r['cycles']:>7} {r['open_ms']:>8} {r['cycles_s']:>9} "
            f"{r['reference_s']:>7} {r['ratio']:>8}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
