"""Benchmark: commands on log roots and index folders someone prepared, and SQL that asks
for more than the machine has.

Each case is a real folder built here (a 366 MB ``catalog.json``, FIFOs where side files
belong, a 305 MB ``index.json``, a 300 MB string in a Parquet row) or a statement from the
issue that found them; each command runs as its own process, measured by a fresh parent
(wall seconds, peak RSS from ``RUSAGE_CHILDREN``, ``hostile.run_cli``). The outcome must be
the documented one: a clear line (exit 2 or 3), or the command's normal answer with the
bad side file ignored; never a hang or a traceback. The anchor is ``info`` on the honest
root, in the same run.

    .venv/bin/python bench/bench_hostile_folders.py
    .venv/bin/python bench/bench_hostile_folders.py --json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.trace_audit.conftest import T0_NS, write_log
from tests.trace_runtime import hostile

_BIG = 366 * 10**6


def _root(base: Path, name: str) -> Path:
    return write_log(base / name, robot_id="r1", max_segment_s=3.0)


def _padded_json(path: Path, size: int, key: str) -> None:
    """A valid JSON object of ``size`` bytes: one long string under ``key``."""
    head = f'{{"{key}": "'.encode()
    with path.open("wb") as f:
        f.write(head)
        block = b"x" * 2**20
        left = size - len(head) - 2
        while left > 0:
            f.write(block[: min(left, len(block))])
            left -= len(block)
        f.write(b'"}')


def _string_row(index: Path) -> None:
    """Replace one decisions file with the same rows, the first ``command`` 300 MB long."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    target = sorted((index / "decisions").rglob("*.parquet"))[0]
    table = pq.read_table(target)
    commands = table.column("command").to_pylist()
    commands[0] = "x" * 300_000_000
    at = table.schema.get_field_index("command")
    table = table.set_column(at, table.schema.field(at), pa.array(commands, pa.string()))
    pq.write_table(table, target)  # the table keeps its schema and its metadata


def cases(base: Path) -> list[tuple[str, list[str]]]:
    """(case, command line) pairs over freshly built folders."""
    t = f"{T0_NS / 1e9 + 2.0:.1f}"
    honest = _root(base, "honest")
    out: list[tuple[str, list[str]]] = [("anchor: honest root", ["info", str(honest)])]

    big = _root(base, "big-catalog")
    _padded_json(big / "catalog.json", _BIG, "pad")
    for args in (
        ["catalog", str(big)],
        ["explain", str(big), "--t", t],
        ["catalog", str(big), "--refresh"],
    ):
        out.append(("catalog.json of 366 MB", args))

    fifo = _root(base, "fifo-catalog")
    os.mkfifo(fifo / "catalog.json")
    for args in (
        ["catalog", str(fifo)],
        ["explain", str(fifo), "--t", t],
        ["compact", str(fifo), "--tier", "cold", "--older-than", "0"],
    ):
        out.append(("catalog.json is a FIFO", args))
    journal = _root(base, "fifo-journal")
    os.mkfifo(journal / "retention.jsonl")
    out.append(
        (
            "retention.jsonl is a FIFO",
            ["compact", str(journal), "--tier", "cold", "--older-than", "0"],
        )
    )

    index = base / "idx"
    hostile_run = hostile.run_cli(["index", str(honest), "--out", str(index)], timeout_s=120)
    assert hostile_run.code == 0, hostile_run.stderr
    for sql in (
        "SELECT count(*) FROM range(1e12::BIGINT)",
        "SELECT repeat('x', 2000000000)",
        "SELECT list(range(300000000))",
        "SELECT string_agg(i::VARCHAR, ',') FROM range(100000000) t(i)",
    ):
        out.append((f"SQL {sql[:44]}", ["query", str(index), sql]))

    strings = base / "idx-string"
    assert hostile.run_cli(["index", str(honest), "--out", str(strings)]).code == 0
    _string_row(strings)
    out.append(
        ("300 MB string in a row", ["query", str(strings), "SELECT * FROM decisions LIMIT 3"])
    )
    out.append(("300 MB string in a row", ["find", str(strings)]))

    huge = base / "idx-huge"
    assert hostile.run_cli(["index", str(honest), "--out", str(huge)]).code == 0
    _padded_json(huge / "index.json", 305 * 10**6, "format")
    for args in (
        ["query", str(huge), "SELECT 1"],
        ["metrics", "--index", str(huge)],
        ["index", str(honest), "--out", str(huge)],
    ):
        out.append(("index.json of 305 MB", args))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="one JSON row per run")
    parser.add_argument("--timeout", type=float, default=90.0, help="kill a run after this")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-folders-") as tmp:
        for case, command in cases(Path(tmp)):
            run = hostile.run_cli([*command, "--plain"], timeout_s=args.timeout)
            lines = run.stderr.strip().splitlines()
            rows.append(
                {
                    "case": case,
                    "command": " ".join("DIR" if c.startswith(tmp) else c for c in command),
                    "seconds": round(run.seconds, 2),
                    "rss_mb": round(run.rss_mb),
                    "exit": run.code,
                    "stderr": lines[-1][:110] if lines else "",
                    "traceback": "Traceback" in run.stderr,
                }
            )
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return
    print(f"{'case':28} {'command':40} {'s':>6} {'MB':>5} {'exit':>4}  last stderr line")
    for r in rows:
        flag = "  TRACEBACK" if r["traceback"] else ""
        print(
            f"{r['case'][:28]:28} {r['command'][:40]:40} {r['seconds']:>6.2f} "
            f"{r['rss_mb']:>5} {r['exit']:>4}  {r['stderr']}{flag}"
        )


if __name__ == "__main__":
    main()
