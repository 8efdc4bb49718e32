"""An honest ``trace-audit query`` against a bare DuckDB read of the same Parquet files.

    .venv/bin/python bench/bench_query.py [--minutes 10] [--runs 15]
                                          [--work DIR (default: $TMPDIR/trace-bench-query)]
                                          [--against GIT_REF]

A sim log root (two robots, ``--minutes`` each, kept between runs) is indexed; then, whole
processes, in alternating order so neither always runs first on a noisy machine:

- **bare**: ``python -c "import duckdb; ..."`` counting the rows of the index's decisions
  files (the manifest's list, Hive partitions on), what a user who points DuckDB at the
  files pays;
- **query**: ``trace-audit query INDEX "SELECT count(*) FROM decisions"`` (and, with
  ``--against REF``, the same command from git ``REF`` exported to a temporary tree).

Medians of wall time over ``--runs`` and their ratio to bare are printed (DESIGN budget
for the issue: query <= 1.5x bare). Both print the same count, checked.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from sim import RunConfig, run  # noqa: E402
from trace_audit.fleet.index import MANIFEST, build_index  # noqa: E402

SQL = "SELECT count(*) FROM decisions"


def build(work: Path, minutes: float) -> Path:
    """The sim root (kept) and a fresh index of it."""
    root = work / "logs"
    if not (root / "hot").is_dir():
        for n, robot in enumerate(("amr-01", "amr-02")):
            run(
                RunConfig(
                    out=root,
                    total_cycles=int(minutes * 600),
                    seed=7 + n,
                    robot_id=robot,
                    batch_cycles=50,
                    start_ns=n * 1_000_000_000,
                )
            )
    index = work / "index"
    shutil.rmtree(index, ignore_errors=True)
    build_index([root], index)
    return index


def bare_script(index: Path) -> str:
    """The bare read: DuckDB on the decisions files the manifest lists, nothing else."""
    manifest = json.loads((index / MANIFEST).read_text(encoding="utf-8"))
    files = sorted(
        (index / rel).as_posix()
        for entry in manifest["segments"].values()
        for rel in entry["files"]
        if rel.startswith("decisions/")
    )
    return (
        "import duckdb\n"
        f"files = {files!r}\n"
        "sql = 'SELECT count(*) FROM read_parquet(?, hive_partitioning = true)'\n"
        "print(duckdb.execute(sql, [files]).fetchone()[0])\n"
    )


def timed(argv: list[str], tree: Path) -> tuple[float, str]:
    """Wall time and output of ``argv`` run from ``tree`` (``python -m`` imports from the
    working directory before PYTHONPATH: both are the tree's)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    started = time.perf_counter()
    done = subprocess.run(argv, env=env, cwd=tree, check=True, capture_output=True, text=True)
    return time.perf_counter() - started, done.stdout


def export_tree(ref: str, work: Path) -> Path:
    tree = work / f"tree-{ref.replace('/', '_')}"
    shutil.rmtree(tree, ignore_errors=True)
    tree.mkdir(parents=True)
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", ref], check=True, capture_output=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="per robot, sim log")
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument(
        "--work", type=Path, default=Path(tempfile.gettempdir()) / "trace-bench-query"
    )
    parser.add_argument("--against", metavar="GIT_REF", help="also time query from this ref")
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    index = build(args.work, args.minutes)
    files = len(list((index / "decisions").rglob("*.parquet")))
    query = [sys.executable, "-m", "trace_audit.cli", "query", str(index), SQL, "--csv"]
    contenders: dict[str, tuple[list[str], Path]] = {
        "bare": ([sys.executable, "-c", bare_script(index)], REPO),
        "query": (query, REPO),
    }
    if args.against:
        contenders[f"query@{args.against}"] = (query, export_tree(args.against, args.work))
    times: dict[str, list[float]] = {name: [] for name in contenders}
    counts: dict[str, str] = {}
    names = list(contenders)
    for n in range(args.runs):
        for name in names if n % 2 == 0 else names[::-1]:
            seconds, out = timed(*contenders[name])
            times[name].append(seconds)
            counts[name] = out.split()[-1]
    assert len(set(counts.values())) == 1, counts
    bare = statistics.median(times["bare"])
    print(
        f"index: {counts['bare']} decisions in {files} files; {args.runs} runs each, load "
        f"{os.getloadavg()[0]:.2f}"
    )
    for name, runs in times.items():
        median = statistics.median(runs)
        print(f"{name:<24} median {median:.3f} s   {median / bare:.2f}x bare")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
