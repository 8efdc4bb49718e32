"""Benchmark: ``doctor`` against ``verify`` on the same log, in the same run.

``doctor`` runs the verifier and, on top, walks every MCAP record with the reference ``mcap``
library and checks every message (canonical JSON, JSON Schema, stamps, layout, refs). Its
cost is reported as a ratio to ``verify`` alone (the anchor), both on one simulator log
(made with ``trace-sim run --duration`` when missing), interleaved, medians of N runs.

    .venv/bin/python bench/bench_doctor.py                 # 5 runs on a 2-minute log
    .venv/bin/python bench/bench_doctor.py --duration 10m --runs 3 --json
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from trace_audit.doctor import doctor_log
from trace_audit.verify import verify_log


def _log(duration: str, where: Path) -> Path:
    out = where / f"doctor-{duration}.mcap"
    if not out.exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "evaluation.cli",
                "run",
                "--duration",
                duration,
                "--out",
                str(out),
            ],
            check=True,
            capture_output=True,
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", default="2m", help="simulated log length")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    log = _log(args.duration, Path(tempfile.gettempdir()))
    times: dict[str, list[float]] = {"verify (anchor)": [], "doctor": []}
    messages = cycles = 0
    for _ in range(args.runs):
        start = time.perf_counter()
        verify_log(log)
        times["verify (anchor)"].append(time.perf_counter() - start)
        start = time.perf_counter()
        report = doctor_log(log)
        times["doctor"].append(time.perf_counter() - start)
        messages = sum(s.messages for s in report.segments)
        cycles = sum(s.cycles for s in report.segments)
    anchor = statistics.median(times["verify (anchor)"])
    rows = {
        name: {
            "median_s": statistics.median(runs),
            "ratio": statistics.median(runs) / anchor,
            "messages_per_s": messages / statistics.median(runs),
        }
        for name, runs in times.items()
    }
    if args.json:
        print(json.dumps({"log": str(log), "cycles": cycles, "rows": rows}, indent=2))
        return
    print(f"{log}: {cycles} cycles, {messages} messages, {args.runs} runs")
    for name, row in rows.items():
        print(
            f"  {name:16} {row['median_s']:7.3f} s  x{row['ratio']:.2f}  "
            f"{row['messages_per_s']:,.0f} msg/s"
        )


if __name__ == "__main__":
    main()
