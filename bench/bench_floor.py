"""The read commands against the floor: what reading the bytes themselves costs (issue 46).

    .venv/bin/python bench/bench_floor.py [--root DIR] [--sim 2h] [--runs 3] [--vs TREE]
        [--only verify,metrics,index,doctor] [--json]

The floor is ``../shared/bench/floor.py ROOT hash``: every file read, every chunk
decompressed, SHA-256 of every message, in a minimal loop. Beside it, as whole processes,
in rounds (so a load change on a shared machine hits all alike), best of ``--runs``:
``trace-audit verify ROOT --json``, ``metrics ROOT --json``, ``index ROOT --out DIR`` (a new
index each time) and ``doctor ROOT --json``. Printed: the issue's ratios of times (lower is
better) from wall and from CPU time (the child's user + system), with the load average
before and after:

    verify / floor (target <= 2.0), metrics / floor (<= 3.0),
    index / metrics (<= 1.2), doctor / verify (<= 3.0)

The root is a simulator root (``trace-sim run --duration SIM --seed 3``), built once under
``--root`` and kept, so repeated runs read the same bytes. ``--vs TREE``: the same commands
from another checkout (``git archive REV | tar -x -C TREE``) in the same rounds, so a change
is measured against its parent in one run. Every child runs with byte code written
(``PYTHONDONTWRITEBYTECODE`` dropped, the packages compiled first), as an installed user's.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
FLOOR = REPO.parent / "shared" / "bench" / "floor.py"
BIN = Path(sys.executable).parent
PACKAGES = ("trace_runtime", "trace_audit", "sim", "evaluation")

# Each ratio: (numerator, denominator, target); times, so lower is better.
RATIOS: dict[str, tuple[str, str, float]] = {
    "verify/floor": ("verify", "floor", 2.0),
    "metrics/floor": ("metrics", "floor", 3.0),
    "index/metrics": ("index", "metrics", 1.2),
    "doctor/verify": ("doctor", "verify", 3.0),
}


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def environment(tree: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
    return env


def timed(args: list[str], env: dict[str, str], ok: tuple[int, ...] = (0,)) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one whole process, which must exit in ``ok``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(args, check=False, capture_output=True, env=env)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode not in ok:
        sys.exit(f"{' '.join(args)}: exit {done.returncode}: {done.stderr.decode()[-400:]}")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return wall, cpu


@dataclass
class Target:
    """One command of one tree, and its best wall and CPU time so far."""

    name: str
    run: Callable[[], tuple[float, float]]
    wall: float = float("inf")
    cpu: float = float("inf")
    samples: list[tuple[float, float]] = field(default_factory=list)

    def once(self) -> None:
        wall, cpu = self.run()
        self.samples.append((round(wall, 3), round(cpu, 3)))
        self.wall, self.cpu = min(self.wall, wall), min(self.cpu, cpu)


def targets_of(tree: Path, root: Path, work: Path, only: AbstractSet[str]) -> dict[str, Target]:
    env = environment(tree)
    ta = str(BIN / "trace-audit")
    index_dir = work / f"idx-{abs(hash(str(tree)))}"

    def index() -> tuple[float, float]:
        shutil.rmtree(index_dir, ignore_errors=True)
        return timed([ta, "index", str(root), "--out", str(index_dir), "--json"], env)

    commands: dict[str, Callable[[], tuple[float, float]]] = {
        "verify": lambda: timed([ta, "verify", str(root), "--json"], env, ok=(0, 1)),
        "metrics": lambda: timed([ta, "metrics", str(root), "--json"], env),
        "index": index,
        "doctor": lambda: timed([ta, "doctor", str(root), "--json"], env, ok=(0, 1)),
    }
    return {name: Target(name, run) for name, run in commands.items() if not only or name in only}


def ratios(targets: dict[str, Target], floor: Target) -> dict[str, dict[str, float]]:
    every = {**targets, "floor": floor}
    out = {}
    for key, (top, bottom, target) in RATIOS.items():
        if top not in every or bottom not in every:
            continue
        out[key] = {
            "wall": round(every[top].wall / every[bottom].wall, 2),
            "cpu": round(every[top].cpu / every[bottom].cpu, 2),
            "target": target,
        }
    return out


def build_root(root: Path, sim: str) -> None:
    if (root / "hot").is_dir():
        return
    args = [str(BIN / "trace-sim"), "run", "--duration", sim, "--seed", "3", "--out", str(root)]
    subprocess.run(args, check=True, capture_output=True, env=environment(REPO))


def measure(
    root: Path,
    runs: int,
    vs: Path | None,
    work: Path,
    only: AbstractSet[str] = frozenset(),
) -> dict[str, object]:
    """Every target of this tree (and ``vs``), in rounds; the best of ``runs`` of each."""
    floor_env = environment(REPO)
    floor = Target(
        "floor", lambda: timed([sys.executable, str(FLOOR), str(root), "hash"], floor_env)
    )
    trees = {"this": REPO, **({"vs": vs} if vs is not None else {})}
    for tree in trees.values():
        subprocess.run(
            [sys.executable, "-m", "compileall", "-q", *(str(tree / p) for p in PACKAGES)],
            check=True, capture_output=True, env=environment(tree),
        )  # fmt: skip
    by_tree = {label: targets_of(tree, root, work, only) for label, tree in trees.items()}
    before = load()
    for _ in range(runs):
        floor.once()
        for targets in by_tree.values():
            for target in targets.values():
                target.once()
    result: dict[str, object] = {"load_before": before, "load_after": load(), "runs": runs}
    result["floor"] = {"wall": round(floor.wall, 3), "cpu": round(floor.cpu, 3)}
    for label, targets in by_tree.items():
        result[label] = {
            "tree": str(trees[label]),
            "best": {
                n: {"wall": round(t.wall, 3), "cpu": round(t.cpu, 3)} for n, t in targets.items()
            },
            "samples": {n: t.samples for n, t in targets.items()},
            "ratios": ratios(targets, floor),
        }
    return result


def show(result: dict[str, object]) -> None:
    print(f"load average {result['load_before']} before, {result['load_after']} after; "
          f"best of {result['runs']}; floor {result['floor']}")  # fmt: skip
    for label in ("this", "vs"):
        part = result.get(label)
        if not isinstance(part, dict):
            continue
        print(f"{label}: {part['tree']}  best (s): {json.dumps(part['best'])}")
        for key, r in part["ratios"].items():
            verdict = "met" if r["wall"] <= r["target"] else "not met"
            print(f"| {key} <= {r['target']} | wall {r['wall']}x | cpu {r['cpu']}x | {verdict} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", type=Path, default=Path("/tmp/floor-bench/root"))
    parser.add_argument("--sim", default="2h", help="the simulator root's duration, if built")
    parser.add_argument("--runs", type=int, default=3, help="best of this many, each figure")
    parser.add_argument("--vs", type=Path, help="another checkout, measured in the same rounds")
    parser.add_argument("--json", action="store_true", help="one JSON object on stdout")
    parser.add_argument(
        "--only", default="", help="these commands only (comma-separated), beside the floor"
    )
    args = parser.parse_args()
    if not FLOOR.is_file():
        sys.exit(f"the floor {FLOOR} is not there")
    build_root(args.root, args.sim)
    work = args.root.parent / "floor-work"
    work.mkdir(exist_ok=True)
    result = measure(args.root, args.runs, args.vs, work, set(filter(None, args.only.split(","))))
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        show(result)


if __name__ == "__main__":
    main()
