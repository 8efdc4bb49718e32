"""Benchmark: ``trace-audit info|verify|metrics`` on files an attacker prepared.

Every file carries a valid TRACE header and ``trace.session`` record so it reaches the deep
code; it is built from the outside with the plain ``mcap`` library
(``tests/trace_runtime/hostile.py``). Each command runs as its own process, measured by a
fresh parent (wall seconds, peak RSS from ``RUSAGE_CHILDREN``). The budget (DESIGN.md,
"Failure behaviour"): exit 3 with one line on stderr, or a ``damaged`` finding from verify
(exit 1), within 2 s and 256 MB each. The anchor is ``info`` on an honest 200-cycle log.

    .venv/bin/python bench/bench_hostile.py
    .venv/bin/python bench/bench_hostile.py --json
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.trace_runtime import hostile
from tests.trace_runtime.conftest import write_log

BUDGET_S = 2.0
BUDGET_MB = 256.0

FILES: dict[str, Callable[[Path], Path]] = {
    "(a) zstd 1 GiB zeros, declared": hostile.zstd_bomb,
    "(b) zstd 1 GiB zeros, declared 4 KB": lambda p: hostile.zstd_bomb(p, declared=4096),
    "(b) same, crashed (no summary)": lambda p: hostile.zstd_bomb(p, declared=4096, summary=False),
    "(c) 16M messages, one chunk": hostile.flood,
    "(c) 16M messages, 245 chunks": lambda p: hostile.flood(p, chunks=245),
    "(c) same, crashed (no summary)": lambda p: hostile.flood(p, chunks=245, summary=False),
    "(c) 100k messages, 2000 a chunk": lambda p: hostile.flood(p, total=100_000, chunks=50),
    "(d) chunk declares 2**62 bytes": hostile.huge_declared,
    "(d) same, crashed (no summary)": lambda p: hostile.huge_declared(p, summary=False),
    "(e) lz4 1 GiB zeros, declared": hostile.lz4_bomb,
    "(e) lz4 1 GiB zeros, declared 4 KB": lambda p: hostile.lz4_bomb(p, declared=4096),
}


def _nested(root: Path) -> Path:
    honest = root / "honest-20.mcap"
    write_log(honest, 20)
    deep = hostile.deep_json(100_000)
    return hostile.rewrite(
        honest, root / "nested.mcap", lambda t, c, d: deep if t == "/trace/action" and c == 5 else d
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="one JSON row per run")
    parser.add_argument("--timeout", type=float, default=60.0, help="kill a run after this")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-hostile-") as tmp:
        root = Path(tmp)
        write_log(root / "honest.mcap", 200)
        files = {"anchor: honest 200 cycles": root / "honest.mcap"}
        for i, (name, build) in enumerate(FILES.items()):
            files[name] = build(root / f"hostile-{i}.mcap")
        files["payload: JSON nested 100,000 deep"] = _nested(root)
        seal = b'{"cycle":0,"t_ns":0,"digests":{},"prev":"' + b"0" * 64 + b'","dropped":0}'
        files["payload: 36k seals inside the limits"] = hostile.flood(
            root / "seals.mcap", total=90 * 400, chunks=400, data=seal
        )
        for name, path in files.items():
            for command in ("info", "verify", "metrics"):
                run = hostile.run_cli([command, str(path), "--plain"], timeout_s=args.timeout)
                lines = run.stderr.strip().splitlines()
                verdict = _verdict(run, command, lines, readable=not name.startswith("("))
                rows.append(
                    {
                        "file": name,
                        "kb": round(path.stat().st_size / 1024),
                        "command": command,
                        "seconds": round(run.seconds, 2),
                        "rss_mb": round(run.rss_mb),
                        "exit": run.code,
                        "verdict": verdict,
                        "stderr": lines[-1][:90] if lines else "",
                    }
                )
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return
    print(f"budget: <= {BUDGET_S} s and <= {BUDGET_MB:.0f} MB peak RSS per run\n")
    print(f"{'file':38} {'KB':>5} {'command':8} {'s':>6} {'MB':>5} {'exit':>4}  verdict")
    for r in rows:
        print(
            f"{r['file']:38} {r['kb']:>5} {r['command']:8} {r['seconds']:>6.2f} "
            f"{r['rss_mb']:>5} {r['exit']:>4}  {r['verdict']}"
        )


def _verdict(run: hostile.Run, command: str, lines: list[str], *, readable: bool) -> str:
    """ok: the documented outcome within budget. A bomb or flood must be refused (exit 3,
    one line) or be a ``damaged`` finding; a readable file with hostile payloads may also
    read (exit 0) or have findings (exit 1), but never a traceback."""
    within = run.seconds <= BUDGET_S and run.rss_mb <= BUDGET_MB
    if "Traceback" in run.stderr:
        return "TRACEBACK"
    if run.code == -9:
        return "KILLED (timeout)"
    if readable and run.code in (0, 1):
        shape = True
    elif command == "verify" and run.code == 1:
        shape = "damaged" in run.stdout
    else:
        shape = run.code == 3 and len(lines) == 1
    if shape and within:
        return "ok"
    return "over budget" if shape else f"wrong outcome: {lines[-1][:60] if lines else ''}"


if __name__ == "__main__":
    main()
