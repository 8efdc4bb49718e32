"""Every read-speed budget in one run: the shared anchor's ratios and the rest beside them.

    .venv/bin/python bench/bench_budgets.py [--runs 3] [--sim 30m] [--anchor PATH] [--json]
        [--floor-sim 2h] [--floor-root DIR] [--no-floor]

1. ``../shared/bench/perf_ratio.py`` (the shared anchor; its docstring defines each anchor)
   run as is, with ``PERF_RUNS`` and ``PERF_SIM`` from ``--runs`` and ``--sim``: logger
   built records and plain dicts, metrics, verify and cold compaction against the plain
   ``mcap`` library, and start-up.
2. On a simulator root of the same kind (``trace-sim run --duration SIM --seed 3``, routine
   operation, the anchor's own settings), the budgets the anchor does not measure, whole
   processes, best of ``--runs``:
   - simulator + logger, cycles a second of the ``trace-sim run`` process (wall clock);
   - ``index`` against ``metrics`` and ``doctor`` against ``verify`` (speed ratios: the
     other command's time over this one's);
   - ``iter_decision_fields`` over the root, decisions a second in one process (open
     included);
   - cold size, bytes a cycle of the root's cold files after ``compact --tier cold``, and
     their ratio to the same segments rewritten with the ``mcap`` Writer's defaults.

3. Against the floor (issue 46, ``bench_floor.py``): ``../shared/bench/floor.py ROOT hash``
   (every chunk decompressed, SHA-256 of every message, in a minimal loop) beside
   ``verify``, ``metrics``, ``index`` and ``doctor`` on a 2 h simulator root (seed 3; kept
   under ``--floor-root`` when given, else built in the run's temporary folder), whole
   processes in rounds, best of ``--runs``: verify / floor, metrics / floor, index /
   metrics, doctor / verify, as times (lower is better), wall and CPU, with their own load
   average. ``--no-floor`` leaves them out.

The load average is printed before and after: read the ratios, the machine is shared.
Every process runs with byte code written and read, as an installed user's does:
``PYTHONDONTWRITEBYTECODE`` is dropped from the children's environment (with it set, every
module changed since its ``.pyc`` is compiled again on each run).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
ANCHOR = REPO.parent / "shared" / "bench" / "perf_ratio.py"
BIN = Path(sys.executable).parent
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
sys.path.insert(0, str(REPO))

from bench_floor import build_root, measure  # noqa: E402
from bench_tiers import mcap_default_bytes  # noqa: E402

# Each budget: its name, the target, and whether the figure is a ratio (higher is better)
# or an absolute rate; cold size is the one where lower is better.
TARGETS: dict[str, tuple[str, float]] = {
    "metrics": ("metrics >= 2.0x the anchor", 2.0),
    "verify": ("verify >= 1.5x the anchor", 1.5),
    "index_vs_metrics": ("index >= 1.0x metrics", 1.0),
    "doctor_vs_verify": ("doctor >= 0.5x verify", 0.5),
    "compact": ("cold compaction >= 0.5x the anchor", 0.5),
    "logger_models": ("logger, built records >= 1.5x the anchor", 1.5),
    "logger_dicts": ("logger, plain dicts >= 1.0x the anchor", 1.0),
    "decision_fields_per_s": ("Log iteration of decision fields >= 50,000 cycles/s", 50_000),
    "sim_cycles_per_s": ("simulator + logger >= 5,000 cycles/s", 5_000),
    "cold_bytes_per_cycle": ("cold size <= 172.5 B/cycle", 172.5),
}
LOWER_IS_BETTER = {"cold_bytes_per_cycle"}
PACKAGES = ("trace_runtime", "trace_audit", "sim", "evaluation")

ITER_FIELDS = r"""
import sys, time
from trace_audit import iter_decision_fields
t = time.perf_counter()
n = sum(1 for _ in iter_decision_fields(sys.argv[1]))
print(n, time.perf_counter() - t)
"""


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def run(args: list[str], ok: tuple[int, ...] = (0,)) -> tuple[float, bytes]:
    """Wall seconds and stdout of one whole process, which must exit with a code in ``ok``."""
    start = time.perf_counter()
    done = subprocess.run(args, check=False, capture_output=True, env=ENV)
    elapsed = time.perf_counter() - start
    if done.returncode not in ok:
        sys.exit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.decode()[-400:]}")
    return elapsed, done.stdout


def timed(args: list[str], ok: tuple[int, ...] = (0,)) -> float:
    return run(args, ok)[0]


def best(runs: int, work: Callable[[], float]) -> float:
    return min(work() for _ in range(runs))


def shared_anchor(path: Path, runs: int, sim: str) -> dict[str, float]:
    env = dict(ENV, PERF_RUNS=str(runs), PERF_SIM=sim)
    done = subprocess.run(
        [sys.executable, str(path)], check=False, cwd=REPO, env=env, capture_output=True, text=True
    )
    if done.returncode != 0:
        sys.exit(f"{path}: exit {done.returncode}: {done.stderr[-400:]}")
    figures: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return figures


def own_budgets(work: Path, runs: int, sim: str) -> dict[str, float]:
    ta, out = str(BIN / "trace-audit"), {}
    root = work / "root"

    def simulate() -> float:
        shutil.rmtree(root, ignore_errors=True)
        seconds, report = run([str(BIN / "trace-sim"), "run", "--duration", sim, "--seed", "3",
                               "--out", str(root), "--json"])  # fmt: skip
        out["cycles"] = json.loads(report)["cycles"]
        return seconds

    sim_s = best(runs, simulate)
    cycles = out["cycles"]
    out["sim_cycles_per_s"] = round(cycles / sim_s)

    metrics_s = best(runs, lambda: timed([ta, "metrics", str(root), "--json"]))
    verify_s = best(runs, lambda: timed([ta, "verify", str(root), "--json"], ok=(0, 1)))

    def index_once() -> float:
        shutil.rmtree(work / "idx", ignore_errors=True)
        return timed([ta, "index", str(root), "--out", str(work / "idx")])

    out["index_vs_metrics"] = round(metrics_s / best(runs, index_once), 3)
    doctor_s = best(runs, lambda: timed([ta, "doctor", str(root), "--json"], ok=(0, 1)))
    out["doctor_vs_verify"] = round(verify_s / doctor_s, 3)

    def iterate() -> float:
        done = subprocess.run(
            [sys.executable, "-c", ITER_FIELDS, str(root)], capture_output=True, text=True,
            check=True, cwd=REPO, env=ENV,
        )  # fmt: skip
        n, seconds = done.stdout.split()
        return float(seconds) / int(n)

    out["decision_fields_per_s"] = round(1 / best(runs, iterate))

    cold = work / "cold"
    shutil.rmtree(cold, ignore_errors=True)
    shutil.copytree(root, cold)
    timed([ta, "compact", str(cold), "--tier", "cold", "--older-than", "0s", "--retention", "off"])
    cold_bytes = sum(p.stat().st_size for p in (cold / "cold").glob("*.mcap"))
    out["cold_bytes_per_cycle"] = round(cold_bytes / cycles, 1)
    out["cold_vs_mcap_default"] = round(cold_bytes / mcap_default_bytes(root), 3)
    return out


def against_floor(args: argparse.Namespace, work: Path) -> dict[str, object]:
    """The floor ratios (``bench_floor.measure``) on a 2 h root, this tree only."""
    root = args.floor_root or work / "floor-root"
    build_root(root, args.floor_sim)
    return measure(root, args.runs, None, work)


def show_floor(floor: dict[str, object]) -> None:
    ours = floor["this"]
    assert isinstance(ours, dict)
    print(
        f"against the floor (floor.py hash, {floor['floor']} s; load average "
        f"{floor['load_before']} before, {floor['load_after']} after), times, lower is better:"
    )
    for key, r in ours["ratios"].items():
        met = "met" if r["wall"] <= r["target"] else "not met"
        print(f"| {key} <= {r['target']}x | {r['wall']}x wall, {r['cpu']}x CPU | {met} |")


def verdict(key: str, value: float) -> str:
    target = TARGETS[key][1]
    if key in LOWER_IS_BETTER:
        return "met" if value <= target else f"not met ({value / target:.2f}x the budget)"
    return "met" if value >= target else f"not met ({value / target:.2f} of the budget)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="best of this many, each figure")
    parser.add_argument("--sim", default="30m", help="the simulator root's duration")
    parser.add_argument("--anchor", type=Path, default=ANCHOR, help="perf_ratio.py")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    parser.add_argument("--floor-sim", default="2h", help="the floor root's duration")
    parser.add_argument("--floor-root", type=Path, help="keep the floor root here (built once)")
    parser.add_argument("--no-floor", action="store_true", help="leave the floor ratios out")
    args = parser.parse_args()
    if not args.anchor.is_file():
        sys.exit(f"the shared anchor {args.anchor} is not there (--anchor PATH)")

    subprocess.run(
        [sys.executable, "-m", "compileall", "-q", *(str(REPO / p) for p in PACKAGES)],
        check=True, capture_output=True, env=ENV,
    )  # fmt: skip
    before = load()
    figures = shared_anchor(args.anchor, args.runs, args.sim)
    with tempfile.TemporaryDirectory(prefix="trace-budgets-") as work:
        figures |= own_budgets(Path(work), args.runs, args.sim)
        floor = None if args.no_floor else against_floor(args, Path(work))
    result: dict[str, Any] = {
        "load_before": before,
        "load_after": load(),
        "figures": figures,
        "floor": floor,
    }
    result["budgets"] = [
        {"budget": name, "measured": figures[key], "verdict": verdict(key, figures[key])}
        for key, (name, _) in TARGETS.items()
    ]
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"load average {before} before, {result['load_after']} after; sim {args.sim}")
    for row in result["budgets"]:
        print(f"| {row['budget']} | {row['measured']} | {row['verdict']} |")
    print(f"start-up (python -c pass / trace-audit --help): {figures.get('startup')}")
    if floor is not None:
        show_floor(floor)


if __name__ == "__main__":
    main()
