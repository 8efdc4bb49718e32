"""Instructions per cycle of the logger, counted by valgrind: a figure a busy machine does
not move, for before/after comparisons where wall-clock ratios swing by more than a change.

    .venv/bin/python bench/bench_logger_instructions.py [--cycles 400] [--vs TREE]

Each case runs this script under ``valgrind --tool=cachegrind`` twice, with ``--cycles``
cycles and with none, in the same way (records built first, the same warm-up), and reports
the difference divided by the cycles. ``PYTHONHASHSEED`` is fixed: dict layouts otherwise
move the count by ~2%. User space only: the kernel's share of a write is not counted, and
OpenSSL runs without the SHA extensions under valgrind, so hashing weighs more than on the
hardware. ``--vs TREE`` counts another checkout (e.g. ``main``) the same way, for a ratio.

Cases (a synthetic 4.3 KB cycle with one ``sensor()`` call):
- batched: the synchronous logger writing 256 cycles a chunk (the writer catching up);
- paced: a chunk per cycle, as a robot's writer at its control rate;
- control: the control thread only (a synchronous logger whose cycles are never written);
each with the records built, and handed over as plain dicts.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

CASES = ("batched", "paced", "control")
KINDS = ("built", "dicts")


def _child(case: str, kind: str, cycles: int) -> None:
    from trace_runtime import AuditLogger, LoggerConfig
    from trace_runtime.testing import synthetic_cycle

    records: list[tuple[object, ...]] = [synthetic_cycle(i) for i in range(300)]
    if kind == "dicts":
        records = [tuple(r.model_dump(by_alias=True) for r in c) for c in records]  # type: ignore[attr-defined]
    batch = {"batched": 256, "paced": 1, "control": 10**9}[case]
    config = LoggerConfig(threaded=False, batch_cycles=batch, fsync_interval_s=None)
    log = AuditLogger(Path(tempfile.mkdtemp()) / "x.mcap", robot_id="b", config=config)
    for i in range(20 + cycles):  # 20 warm-up cycles in every run: first-use set-up
        p, b, a, e = records[i % len(records)]
        with log.cycle(i * 100_000_000) as c:
            c.sensor("/sensors/lidar", {"ranges": [1.5, 1.6, 1.7], "cluster": i})
            c.perception(p)
            c.belief(b)
            c.action(a)
            c.execution(e)
    if case == "control":
        os._exit(0)  # the cycles are never written: the count is the control thread's
    log.close(timeout_s=None)


def _count(tree: Path, case: str, kind: str, cycles: int) -> int:
    env = {**os.environ, "PYTHONHASHSEED": "1", "PYTHONPATH": str(tree)}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    command = [
        "valgrind",
        "--tool=cachegrind",
        "--cache-sim=no",
        "--cachegrind-out-file=/dev/null",
        sys.executable,
        str(Path(__file__).resolve()),
        "--child",
        case,
        kind,
        str(cycles),
    ]
    done = subprocess.run(command, env=env, cwd=tree, capture_output=True, text=True, check=True)
    found = re.search(r"I\s+refs:\s+([\d,]+)", done.stderr)
    if found is None:
        raise RuntimeError(f"no instruction count from valgrind:\n{done.stderr[-2000:]}")
    return int(found.group(1).replace(",", ""))


def per_cycle(tree: Path, case: str, kind: str, cycles: int) -> float:
    return (_count(tree, case, kind, cycles) - _count(tree, case, kind, 0)) / cycles


def main() -> None:
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=400)
    parser.add_argument("--vs", type=Path, help="another checkout to count the same way")
    args = parser.parse_args()
    here = Path(__file__).resolve().parent.parent
    print(f"instructions per cycle ({args.cycles} cycles minus none, valgrind cachegrind)")
    for case in CASES:
        for kind in KINDS:
            ours = per_cycle(here, case, kind, args.cycles)
            line = f"  {case:8s} {kind:6s} {ours / 1000:8.1f}k"
            if args.vs is not None:
                theirs = per_cycle(args.vs.resolve(), case, kind, args.cycles)
                line += f"   vs {theirs / 1000:8.1f}k   ratio {ours / theirs:.3f}"
            print(line, flush=True)


if __name__ == "__main__":
    main()
