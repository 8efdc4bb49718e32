"""Fleet benchmark: index build against metrics, query latency on 10 robot-days, metrics
from the index against metrics from the logs, and a Dask cluster with 1 and 2 workers.

    .venv/bin/python bench/bench_fleet.py [--minutes 30] [--robot-days 10] [--repeats 3]
                                          [--work DIR (default: $TMPDIR/trace-bench-fleet)]
                                          [--against GIT_REF] [--build-only] [--skip-dask]

1. **Index build, CPU per core**: a real sim log root (two robots, ``--minutes`` each,
   routine operation with the paper's fault rates) is scored by ``compute_metrics`` (one
   process) and indexed by ``build_index`` into a fresh directory (one process), in
   alternating rounds; medians of CPU seconds, cycles/s each and the ratio index/metrics.
   With ``--against REF``, ``trace-audit metrics`` and ``trace-audit index`` (one job each,
   fresh processes, CPU of the process) are also timed for this tree and for git ``REF``
   (exported to a temporary tree), order alternating, so a change's before and after are
   read in one run (``--build-only`` stops after step 1).
2. **10 robot-days (8.6 M decisions)**: simulating 8.6 M cycles here takes hours, so the
   index rows are *synthetic*: the real index's decisions (and their entities) replicated
   24 x per robot-day with fresh cycle numbers, times (10 Hz), segment names and robots,
   written in the index layout (one file per robot and day). Only the rows are synthetic;
   the query engine, the files and the sizes are real.
3. **Query latency** on that index (library call, DuckDB views set up each time, medians):
   the STOP-near-a-person question (``find_decisions``) and a per-robot/day ET table.
4. **Index bytes per decision** (all four tables) on the real index and the synthetic one.
5. **Metrics over the 10 robot-days**: ``index_metrics --by robot,day`` timed; from the
   logs, the measured single-process rate of step 1 applied to the same decision count
   (projected: re-reading 8.6 M cycles here would take ~15 CPU minutes).
6. **Dask**: a real ``dask scheduler`` and worker processes on localhost (free ports),
   ``compute_metrics`` of the real root with 1 worker, then 2 (one task per segment),
   medians of wall time and the ratio. The machine has 2 shared cores: the load is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from sim import RunConfig, run  # noqa: E402
from trace_audit.fleet.find import find_decisions  # noqa: E402
from trace_audit.fleet.index import MANIFEST, build_index  # noqa: E402
from trace_audit.fleet.metrics import index_metrics  # noqa: E402
from trace_audit.fleet.query import connect, run_query  # noqa: E402
from trace_audit.fleet.tables import INDEX_FORMAT, INDEX_VERSION, schema  # noqa: E402
from trace_audit.metrics import MetricsConfig, compute_metrics  # noqa: E402

ROBOT_DAY = 864_000
PAPER_ROBOTS, PAPER_DAYS = 100_000, 183


def build_logs(root: Path, minutes: float) -> int:
    """Two robots of routine operation in one log root (kept between runs)."""
    if (root / "hot").is_dir():
        return sum(1 for _ in (root / "hot").glob("*.mcap"))
    cycles = int(minutes * 600)
    for n, robot in enumerate(("amr-01", "amr-02")):
        run(
            RunConfig(
                out=root,
                total_cycles=cycles,
                seed=2024 + n,
                robot_id=robot,
                batch_cycles=50,
                start_ns=n * 1_000_000_000,
            )
        )
    return 2


def cpu(call: Callable[[], object]) -> tuple[float, object]:
    started = time.process_time()
    result = call()
    return time.process_time() - started, result


def bench_build(root: Path, work: Path, repeats: int) -> dict[str, float]:
    metrics_s: list[float] = []
    index_s: list[float] = []
    decisions = 0
    for _ in range(repeats):
        # As `trace-audit metrics` runs without --failures: nothing listed.
        seconds, report = cpu(lambda: compute_metrics([root], MetricsConfig(max_listed=0)))
        metrics_s.append(seconds)
        decisions = report.overall.decisions  # type: ignore[attr-defined]
        shutil.rmtree(work / "index", ignore_errors=True)
        seconds, _ = cpu(lambda: build_index([root], work / "index"))
        index_s.append(seconds)
    m, i = statistics.median(metrics_s), statistics.median(index_s)
    return {
        "decisions": decisions,
        "metrics_cpu_s": m,
        "index_cpu_s": i,
        "metrics_cycles_per_s": decisions / m,
        "index_cycles_per_s": decisions / i,
        "ratio_index_to_metrics": m / i,
    }


def _cli_cpu(tree: Path, *args: str) -> float:
    """CPU seconds (user + system, the process and its children) of one ``trace-audit``
    command run from ``tree``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", *args, "--json"],
        env={**os.environ, "PYTHONPATH": str(tree)},
        check=True,
        stdout=subprocess.DEVNULL,
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def bench_against(
    ref: str, root: Path, work: Path, repeats: int, decisions: int
) -> dict[str, object]:
    """``trace-audit metrics`` and ``trace-audit index`` (fresh processes, one job each,
    as a user runs them) for this tree and for git ``ref``, rounds alternating."""
    tree = work / f"tree-{ref.replace('/', '_')}"
    shutil.rmtree(tree, ignore_errors=True)
    tree.mkdir(parents=True)
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", ref], check=True, capture_output=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    trees = [("this", REPO), (ref, tree)]
    rounds: dict[str, list[tuple[float, float]]] = {"this": [], ref: []}
    for n in range(repeats):
        for name, source in trees if n % 2 == 0 else trees[::-1]:  # ABBA: neither always first
            metrics_s = _cli_cpu(source, "metrics", str(root), "--jobs", "1")
            out = work / f"index-{name.replace('/', '_')}"
            shutil.rmtree(out, ignore_errors=True)
            index_s = _cli_cpu(source, "index", str(root), "--out", str(out), "--jobs", "1")
            rounds[name].append((metrics_s, index_s))
    result: dict[str, object] = {}
    for name, runs in rounds.items():
        m = statistics.median(r[0] for r in runs)
        i = statistics.median(r[1] for r in runs)
        result[name] = {
            "metrics_cycles_per_s": decisions / m,
            "index_cycles_per_s": decisions / i,
            "ratio_index_to_metrics": m / i,
            "ratios_per_round": [round(r[0] / r[1], 3) for r in runs],
        }
    this_i = statistics.median(r[1] for r in rounds["this"])
    ref_i = statistics.median(r[1] for r in rounds[ref])
    result["index_cpu_this_over_ref"] = this_i / ref_i
    shutil.rmtree(tree, ignore_errors=True)
    return result


def index_bytes(index: Path) -> int:
    return sum(p.stat().st_size for p in index.rglob("*.parquet"))


def synthesize(real: Path, out: Path, robot_days: int) -> int:
    """Replicate the real index's rows into ``robot_days`` robot-days (see module doc)."""
    import duckdb

    shutil.rmtree(out, ignore_errors=True)
    con = connect(real, confined=False)  # it writes the synthetic files with COPY
    con.execute(
        "CREATE TABLE base AS SELECT row_number() OVER (ORDER BY robot, cycle) - 1 AS i, * "
        "EXCLUDE (explain) FROM decisions"
    )
    con.execute(
        "CREATE TABLE ents AS SELECT b.i, e.* EXCLUDE (robot, day, segment, cycle, t_ns) "
        "FROM entities e JOIN base b USING (robot, segment, cycle)"
    )
    block = int(con.execute("SELECT count(*) FROM base").fetchone()[0])  # type: ignore[index]
    per_day = ROBOT_DAY // block or 1
    day0_ns = 1_764_547_200 * 1_000_000_000  # 2025-12-01 00:00 UTC
    written = 0
    segments: dict[str, object] = {}
    for r in range(robot_days):
        robot = f"amr-{r:03d}"
        day = time.strftime("%Y-%m-%d", time.gmtime(day0_ns // 1_000_000_000))
        seq = f"(h.h * {block} + b.i)"
        t_ns = f"({day0_ns} + {seq} * 100000000)"
        replaced = {
            "segment": f"'{robot}_' || lpad(h.h::VARCHAR, 6, '0') || '.mcap'",
            "segment_path": f"'/fleet/{robot}/hot/{robot}_' || lpad(h.h::VARCHAR, 6, '0') "
            "|| '.mcap'",
            "cycle": seq,
            "t_ns": t_ns,
            "hour": f"strftime(make_timestamp({t_ns} // 1000), '%Y-%m-%d %H:00')",
        }
        for table, source in (("decisions", "base b"), ("entities", "ents b")):
            columns = ", ".join(
                f"{replaced.get(c, f'b.{c}')} AS {c}"
                if table == "decisions" or c in ("segment", "cycle", "t_ns")
                else f'b."{c}" AS "{c}"'
                for c in schema(table).names
            )
            target = out / table / f"robot={robot}" / f"day={day}" / "synthetic.parquet"
            target.parent.mkdir(parents=True, exist_ok=True)
            con.execute(
                f"COPY (SELECT {columns} FROM {source}, range({per_day}) h(h) "
                f"ORDER BY h.h, b.i) TO '{target}' (FORMAT parquet, COMPRESSION zstd)"
            )
        # One segments row a robot, the real first one's with this robot's names and times:
        # what a reader of the segments table (check --index: period, start) needs.
        target = out / "segments" / f"robot={robot}" / f"day={day}" / "synthetic.parquet"
        target.parent.mkdir(parents=True, exist_ok=True)
        renamed = {
            "segment": f"'{robot}_000000.mcap'",
            "segment_path": f"'/fleet/{robot}/hot/{robot}_000000.mcap'",
            "start_ns": str(day0_ns),
            "end_ns": str(day0_ns + (block * per_day - 1) * 100_000_000),
            "first_cycle": "0",
            "last_cycle": str(block * per_day - 1),
            "cycles": str(block * per_day),
        }
        columns = ", ".join(f"{renamed.get(c, c)} AS {c}" for c in schema("segments").names)
        con.execute(
            f"COPY (SELECT {columns} FROM (SELECT * FROM segments ORDER BY robot, number "
            f"LIMIT 1)) TO '{target}' (FORMAT parquet, COMPRESSION zstd)"
        )
        written += block * per_day
        segments[f"{robot}/synthetic"] = {
            "files": [  # the views read the files a manifest lists
                f"{table}/robot={robot}/day={day}/synthetic.parquet"
                for table in ("decisions", "entities", "segments")
            ],
            "decisions": block * per_day,
        }
    con.close()
    del duckdb
    manifest = json.loads((real / MANIFEST).read_text())
    body = {
        "format": INDEX_FORMAT,
        "version": INDEX_VERSION,
        "config": manifest["config"],
        "segments": segments,
        "synthetic": True,
    }
    (out / MANIFEST).write_text(json.dumps(body, indent=1))
    return written


def median_wall(call: Callable[[], object], repeats: int) -> tuple[float, object]:
    times: list[float] = []
    result: object = None
    for _ in range(repeats):
        started = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - started)
    return statistics.median(times), result


def bench_dask(root: Path, work: Path, repeats: int) -> dict[str, float]:
    from concurrent.futures import Executor

    from trace_audit.fleet.cluster import dask_executor
    from trace_audit.fleet.local import LocalDask

    def metrics_on(executor: Executor) -> object:
        return compute_metrics([root], MetricsConfig(), executor=executor)

    out: dict[str, float] = {}
    with LocalDask(work / "dask", pythonpath=REPO) as cluster:
        cluster.add_worker()
        with dask_executor(cluster.address) as executor:
            metrics_on(executor)  # warm the worker: imports, first segment open
            out["dask_1_worker_s"], _ = median_wall(lambda: metrics_on(executor), repeats)
        cluster.add_worker()
        time.sleep(5)
        with dask_executor(cluster.address) as executor:
            metrics_on(executor)
            out["dask_2_workers_s"], _ = median_wall(lambda: metrics_on(executor), repeats)
    out["dask_speedup_2_over_1"] = out["dask_1_worker_s"] / out["dask_2_workers_s"]
    out["load_average_1min"] = os.getloadavg()[0]
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="per robot, real sim log")
    parser.add_argument("--robot-days", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--work", type=Path, default=Path(tempfile.gettempdir()) / "trace-bench-fleet"
    )
    parser.add_argument("--skip-dask", action="store_true")
    parser.add_argument("--against", metavar="GIT_REF", help="also time step 1 for this ref")
    parser.add_argument("--build-only", action="store_true", help="stop after step 1")
    args = parser.parse_args()
    work: Path = args.work
    work.mkdir(parents=True, exist_ok=True)
    root = work / "logs"
    build_logs(root, args.minutes)

    results: dict[str, object] = {"cpus": len(os.sched_getaffinity(0))}
    build = bench_build(root, work, args.repeats)
    results["build"] = build
    if args.against:
        results["build_against"] = bench_against(
            args.against, root, work, args.repeats, int(build["decisions"])
        )
    real = work / "index"
    real_decisions = int(build["decisions"])
    real_bytes = index_bytes(real)
    results["real_index"] = {
        "decisions": real_decisions,
        "bytes": real_bytes,
        "bytes_per_decision": real_bytes / real_decisions,
    }
    if args.build_only:
        json.dump(results, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0

    synth = work / "index-10-robot-days"
    started = time.perf_counter()
    decisions = synthesize(real, synth, args.robot_days)
    synth_bytes = index_bytes(synth)
    results["synthetic_index"] = {
        "decisions": decisions,
        "bytes": synth_bytes,
        "bytes_per_decision": synth_bytes / decisions,
        "written_s": time.perf_counter() - started,
    }

    # What `find` shows (the first 1000 in time order), and the size of the whole answer.
    stop_s, stops = median_wall(
        lambda: find_decisions(synth, action="STOP", near="person", within_m=1.0),
        args.repeats,
    )
    count_sql = (
        "SELECT software_version, count(*) FROM decisions "
        "WHERE command = 'STOP' AND nearest['person'] < 1.0 GROUP BY ALL"
    )
    count_s, count = median_wall(lambda: run_query(synth, count_sql), args.repeats)
    # The same answer by joining the entities table (the general form, for any question
    # about what was seen): one measurement, for comparison.
    join_sql = (
        "SELECT count(*) FROM decisions d SEMI JOIN (SELECT robot, cycle, t_ns FROM entities "
        "WHERE class = 'person' AND distance < 1.0) e USING (robot, cycle, t_ns) "
        "WHERE d.command = 'STOP'"
    )
    join_s, join = median_wall(lambda: run_query(synth, join_sql), 1)
    et_sql = (
        "SELECT robot, day, count(*) AS decisions, avg(et) AS et, avg(dr::INT) AS dr, "
        "avg(tcs) AS tcs FROM decisions GROUP BY ALL ORDER BY robot, day"
    )
    et_s, et_rows = median_wall(lambda: run_query(synth, et_sql), args.repeats)
    metrics_s, report = median_wall(lambda: index_metrics(synth, ["robot", "day"]), args.repeats)

    # Anchor for the confined session `query` runs in (allowed_paths, no external access):
    # the same table on a full DuckDB session over the same files.
    def et_table(confined: bool) -> object:
        con = connect(synth, confined=confined)
        try:
            return con.execute(et_sql).fetchall()
        finally:
            con.close()

    et_open_s, _ = median_wall(lambda: et_table(False), args.repeats)
    et_confined_s, _ = median_wall(lambda: et_table(True), args.repeats)
    results["queries"] = {
        "robot_day_et_table_full_duckdb_s": et_open_s,
        "robot_day_et_table_confined_s": et_confined_s,
        "confined_over_full": et_confined_s / et_open_s,
        "stop_near_person_s": stop_s,
        "stop_near_person_rows_shown": len(stops.rows),  # type: ignore[attr-defined]
        "stop_near_person_count_s": count_s,
        "stop_near_person_total": count.rows[0][1],  # type: ignore[attr-defined]
        "stop_near_person_join_entities_s": join_s,
        "stop_near_person_join_total": join.rows[0][0],  # type: ignore[attr-defined]
        "robot_day_et_table_s": et_s,
        "robot_day_et_rows": len(et_rows.rows),  # type: ignore[attr-defined]
        "metrics_from_index_s": metrics_s,
        "metrics_from_index_decisions": report.overall.decisions,  # type: ignore[attr-defined]
        "metrics_from_logs_projected_cpu_s": decisions / build["metrics_cycles_per_s"],
    }
    if not args.skip_dask:
        results["dask"] = bench_dask(root, work, args.repeats)

    per_decision = results["real_index"]["bytes_per_decision"]  # type: ignore[index]
    paper = PAPER_ROBOTS * PAPER_DAYS * ROBOT_DAY
    scan_s_per_m = et_s / (decisions / 1e6)
    results["paper_projection"] = {
        "decisions": paper,
        "index_bytes": paper * per_decision,
        "index_pb": paper * per_decision / 1e15,
        "full_scan_et_table_core_hours": paper / 1e6 * scan_s_per_m / 3600,
        "month_of_200_robots_s": 200 * 30 * ROBOT_DAY / 1e6 * scan_s_per_m,
    }
    json.dump(results, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
