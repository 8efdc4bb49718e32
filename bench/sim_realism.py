"""Measure how a robotics engineer would judge the simulator's decisions, from its logs alone.

For each seed (faults off, the paper's run shape: five scenarios x 100 cycles) this reports:
the share of cycles whose execution record has a failed compliance check (per rule and per
scenario), the share of non-CONTINUE commands per scenario, and the counterfactuals of the
paper's example cycle (seed 42, t = 20.0 s, faults on).

Run: ``.venv/bin/python bench/sim_realism.py [--seeds 1-10] [--json]``
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

from sim import FaultRates, RunConfig, run
from trace_runtime.flags import split_flags
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_ACTION, TOPIC_EXECUTION


def measure(seed: int, work: Path, faults: FaultRates) -> dict[str, Any]:
    out = work / f"run-{seed}.mcap"
    run(RunConfig(out=out, scenario="all", cycles=100, seed=seed, faults=faults))
    failed_cycles = 0
    cycles = 0
    by_rule: Counter[str] = Counter()
    by_scenario: Counter[str] = Counter()
    commands: dict[str, Counter[str]] = {}
    for cycle in open_log(out).iter_cycles():
        execution = cycle.json(TOPIC_EXECUTION)
        action = cycle.json(TOPIC_ACTION)
        if execution is None or action is None:
            continue
        cycles += 1
        _flags, scenario = split_flags(execution["flags"])
        commands.setdefault(scenario, Counter())[action["command"]] += 1
        failed = [c["rule"] for c in execution["checks"] if not c["passed"]]
        if failed:
            failed_cycles += 1
            by_scenario[scenario] += 1
            by_rule.update(failed)
    return {
        "seed": seed,
        "cycles": cycles,
        "failed_cycles": failed_cycles,
        "failed_by_rule": dict(by_rule),
        "failed_by_scenario": dict(by_scenario),
        "non_continue": {
            s: round(1 - c["CONTINUE"] / sum(c.values()), 3) for s, c in commands.items()
        },
        "commands": {s: dict(c) for s, c in commands.items()},
    }


def paper_example(work: Path) -> dict[str, Any]:
    out = work / "paper.mcap"
    run(RunConfig(out=out, scenario="all", cycles=100, seed=42))
    cycle = open_log(out).cycle_at(20_000_000_000)
    action = cycle.json(TOPIC_ACTION)
    return {
        "cycle": cycle.cycle,
        "command": action["command"],
        "counterfactuals": action["counterfactuals"],
        "factors": [(f["node"], f.get("value")) for f in action["rationale"]["factors"]],
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", default="1-10")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    lo, _, hi = args.seeds.partition("-")
    seeds = list(range(int(lo), int(hi or lo) + 1))
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rows = [measure(s, work, FaultRates.off()) for s in seeds]
        example = paper_example(work)
    total = sum(r["cycles"] for r in rows)
    failed = sum(r["failed_cycles"] for r in rows)
    rules: Counter[str] = Counter()
    for r in rows:
        rules.update(r["failed_by_rule"])
    summary = {
        "seeds": seeds,
        "failed_check_share": round(failed / total, 4),
        "failed_cycles": failed,
        "cycles": total,
        "failed_by_rule": dict(rules),
        "forklift_non_continue_per_seed": {r["seed"]: r["non_continue"]["forklift"] for r in rows},
        "forklift_commands": sum((Counter(r["commands"]["forklift"]) for r in rows), Counter()),
        "paper_example": example,
        "per_seed": rows,
    }
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    print(f"failed-check cycles, faults off: {failed}/{total} = {100 * failed / total:.1f}%")
    print(f"  by rule: {dict(rules)}")
    for r in rows:
        print(
            f"  seed {r['seed']}: failed {r['failed_cycles']} {r['failed_by_scenario']}; "
            f"non-CONTINUE {r['non_continue']}"
        )
    print(f"forklift commands, all seeds: {dict(summary['forklift_commands'])}")
    print(f"paper example (seed 42, t=20.0): {json.dumps(example)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
