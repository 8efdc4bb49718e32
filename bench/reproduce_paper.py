"""Reproduce the paper's Tables II and III with the simulator and ``trace-audit metrics``.

    .venv/bin/python bench/reproduce_paper.py [--seed 42] [--seeds 20] [--out docs/reproduction.md]

Runs the paper's evaluation: 5 scenarios x 100 decision cycles at 10 Hz with faults at the
paper's rates (sensor unavailability 2% LiDAR / 12% camera, evidence link corruption 3% per
entity, causal edge write failures 2%, rationale truncation 2%, counterfactual timeouts
2.5%, audit write timeouts 1%), through the sim library. Computes the metrics from the log
only (``trace_audit.metrics.compute_metrics``, grouped by scenario), repeats the run over
``--seeds`` seeds to show how much a 500-cycle run varies, and writes a markdown report
with the paper's tables beside ours.
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import subprocess
import sys
import tempfile
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from evaluation.baselines import BaselinesReport, MethodResult
from evaluation.baselines.cost import WARM_UP_CYCLES
from evaluation.baselines.evaluate import Spread
from sim import SCENARIOS, FaultRates, RunConfig, RunResult, read_truth, run
from sim.replay import check_counterfactuals
from trace_audit.metrics import MetricsConfig, MetricsReport, compute_metrics
from trace_runtime.flags import split_flags
from trace_runtime.reading.logset import open_log
from trace_runtime.records import TOPIC_ACTION, TOPIC_EXECUTION

# The paper's reported figures (Tables II and III), quoted for comparison only.
PAPER_TABLE_II = {"ET": "98.6 ± 7.0", "TC": "99.0", "DR": "98.1", "Time": "0.12 ms"}
PAPER_TABLE_III = {
    "clear_path": ("96.4%", "0.98", "100%", "96.6%"),
    "ped_crossing": ("99.0%", "0.98", "100%", "98.2%"),
    "ped_close": ("99.5%", "0.99", "100%", "99.0%"),
    "multi_ped": ("98.3%", "0.98", "100%", "98.0%"),
    "forklift": ("100%", "1.00", "99%", "98.8%"),
}
PAPER_COUNTS = {"not fully traceable": 7, "gaps (records)": 5, "not reconstructable": 23}


@dataclass
class Run:
    seed: int
    report: MetricsReport
    truth_counts: dict[str, int]
    example: dict[str, Any] | None = None
    """The paper's example cycle (t = 20.0 s) as logged."""


@dataclass
class Behaviour:
    """A faults-off run, judged as a robotics engineer would (issue 16)."""

    seed: int
    result: RunResult
    cycles: int
    failed_checks: int
    non_continue: dict[str, float]


EXAMPLE_T_NS = 20_000_000_000


def simulate(seed: int, workdir: Path) -> Run:
    out = workdir / f"run-{seed}.mcap"
    result = run(RunConfig(out=out, scenario="all", cycles=100, seed=seed, faults=FaultRates()))
    report = compute_metrics([out], MetricsConfig(by="scenario", max_listed=10_000))
    counts: dict[str, int] = {}
    for line in read_truth(result.truth):  # only to describe what was injected, not to score
        counts[line["kind"]] = counts.get(line["kind"], 0) + 1
    action = open_log(out).cycle_at(EXAMPLE_T_NS).json(TOPIC_ACTION)
    replay = check_counterfactuals(out)
    example = {
        "command": action["command"] if action else None,
        "counterfactuals": action["counterfactuals"] if action else [],
        "rationale": action["rationale"]["text"] if action else "",
        "replay_ok": replay.ok,
        "replayed": replay.counterfactuals,
        "unverifiable": sum(replay.unverifiable.values()),
    }
    return Run(seed, report, counts, example)


def behave(seed: int, workdir: Path) -> Behaviour:
    out = workdir / f"clean-{seed}.mcap"
    result = run(RunConfig(out=out, scenario="all", cycles=100, seed=seed, faults=FaultRates.off()))
    cycles = failed = 0
    commands: dict[str, Counter[str]] = {}
    for cycle in open_log(out).iter_cycles():
        execution, action = cycle.json(TOPIC_EXECUTION), cycle.json(TOPIC_ACTION)
        if execution is None or action is None:
            continue
        cycles += 1
        failed += any(not c["passed"] for c in execution["checks"])
        _flags, scenario = split_flags(execution["flags"])
        commands.setdefault(scenario, Counter())[action["command"]] += 1
    share = {s: 1 - c["CONTINUE"] / sum(c.values()) for s, c in commands.items()}
    return Behaviour(seed, result, cycles, failed, share)


def pct(value: float | None, digits: int = 1) -> str:
    return "n/a" if value is None else f"{value * 100:.{digits}f}%"


def mean_std(values: list[float]) -> str:
    mean = statistics.fmean(values)
    std = statistics.pstdev(values) if len(values) > 1 else 0.0
    return f"{mean * 100:.1f} ± {std * 100:.1f}"


def git_revision() -> str:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parents[1],
        )
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def render(main: Run, sweep: list[Run], seeds: list[int], clean: list[Behaviour]) -> str:
    r = main.report
    o = r.overall
    across = r.across_groups
    assert across is not None
    lines: list[str] = []
    add = lines.append
    add("# Reproducing the paper's evaluation")
    add("")
    add(
        "Generated by `bench/reproduce_paper.py` (do not edit by hand); commit "
        f"`{git_revision()}`, Python {platform.python_version()}."
    )
    add("")
    add(
        "The run: the simulator (`sim.run`) drives the five scenarios, 100 decision cycles each "
        "(500 in all) at 10 Hz, with faults injected at the paper's rates; "
        f"seed {main.seed}. The metrics come from the log alone "
        "(`trace-audit metrics run.mcap --by scenario`); definitions in "
        "[metrics.md](metrics.md). The simulator's fault ground truth is used below only to "
        "say what was injected."
    )
    add("")
    add("## Table II: auditability metrics")
    add("")
    add("| | ET (%) | TC (%) | DR (%) | Time |")
    add("|---|---|---|---|---|")
    add(
        f"| paper (TRACE) | {PAPER_TABLE_II['ET']} † | {PAPER_TABLE_II['TC']} | "
        f"{PAPER_TABLE_II['DR']} | {PAPER_TABLE_II['Time']} |"
    )
    add(
        f"| ours, std across decisions | {o.et.mean * 100:.1f} ± {o.et.std * 100:.1f} | "
        f"{pct(o.tc, 1)[:-1]} | {pct(o.dr, 1)[:-1]} | {r.logging_time} |"
    )
    add(
        f"| ours, std across the 5 scenarios | {across.et.mean * 100:.1f} ± "
        f"{across.et.std * 100:.1f} | {pct(o.tc, 1)[:-1]} | {pct(o.dr, 1)[:-1]} | |"
    )
    add("")
    add("† The paper labels its ± as the std across the 5 scenarios.")
    add("")
    add(f"Counts behind our row (seed {main.seed}):")
    add("")
    add("| | ours | paper |")
    add("|---|---|---|")
    add(f"| decisions logged | {o.decisions} of 500 | 500 |")
    add(
        f"| fully traceable | {o.fully_traceable} ({pct(o.fully_traceable_share.mean)}) | "
        f"493 (98.6%) |"
    )
    add(
        f"| not fully traceable | {o.decisions - o.fully_traceable} | "
        f"{PAPER_COUNTS['not fully traceable']} |"
    )
    add(f"| of which: action names no factors (truncated away) | {_no_factor_count(r)} | — |")
    add(
        f"| ET_partial (mean over decisions) | {o.et_partial.mean:.3f} | 0.98 (failing decisions) |"
    )
    add(
        f"| gaps / missing cycles / seals' declared drops | {o.gaps} / {o.missing_cycles} / "
        f"{o.declared_dropped} | 5 records |"
    )
    add(f"| TC window | {o.window_s:.1f} s, {o.gap_s:.1f} s in gaps | — |")
    add(
        f"| not reconstructable | {o.not_reconstructable} | {PAPER_COUNTS['not reconstructable']} |"
    )
    add(f"| integrity failures | {o.integrity_failed} | — |")
    add(f"| TCS (mean ± std across decisions) | {o.tcs.mean:.3f} ± {o.tcs.std:.3f} | — |")
    add("")
    add(
        "Faults the simulator injected in this run (from its ground-truth sidecar): "
        + ", ".join(f"{k} {v}" for k, v in sorted(main.truth_counts.items()))
        + "."
    )
    add("")
    add("## Table III: per scenario")
    add("")
    add(
        "| scenario | ET paper | ET ours | ET_partial paper | ET_partial ours | TC paper | "
        "TC ours | DR paper | DR ours |"
    )
    add("|---|---|---|---|---|---|---|---|---|")
    groups = {g.name: g for g in r.groups}
    for name in SCENARIOS:
        g = groups.get(name)
        p_et, p_etp, p_tc, p_dr = PAPER_TABLE_III.get(name, ("—",) * 4)
        if g is None:
            add(f"| {name} | {p_et} | — | {p_etp} | — | {p_tc} | — | {p_dr} | — |")
            continue
        add(
            f"| {name} | {p_et} | {pct(g.et.mean)} ({g.fully_traceable}/{g.decisions}) | "
            f"{p_etp} | {g.et_partial.mean:.2f} | {p_tc} | {pct(g.tc, 0)} ({g.gaps} gaps) | "
            f"{p_dr} | {pct(g.dr)} ({g.not_reconstructable} not) |"
        )
    add("")
    add(
        "Ours: ET is the mean ET(d) of the scenario's decisions (fully traceable / logged in "
        "brackets); TC counts gaps in the intervals that end in that scenario."
    )
    add("")
    add(f"## How much a 500-cycle run varies ({len(seeds)} seeds)")
    add("")
    add(
        "The same evaluation repeated with seeds "
        f"{seeds[0]}..{seeds[-1]}; mean ± std across seeds of each run's overall value:"
    )
    add("")
    add("| metric | across seeds | min | max |")
    add("|---|---|---|---|")
    for label, values in _sweep_rows(sweep):
        add(f"| {label} | {mean_std(values)} | {min(values) * 100:.1f} | {max(values) * 100:.1f} |")
    add("")
    lines.extend(_behaviour(main, clean))
    add("## Differences, honestly")
    add("")
    for paragraph in _differences(main, sweep):
        add(paragraph)
        add("")
    return "\n".join(lines).rstrip() + "\n"


def _behaviour(main: Run, clean: list[Behaviour]) -> list[str]:
    """The decisions the metrics audit, judged as a robotics engineer would (issue 16)."""
    out = ["## The robot's decisions, with faults off", ""]
    seeds = f"{clean[0].seed}..{clean[-1].seed}"
    cycles = sum(b.cycles for b in clean)
    failed = sum(b.failed_checks for b in clean)
    out.append(
        f"The auditability figures mean something only if the decisions are sound. Seeds "
        f"{seeds}, the same 500-cycle runs with no fault injected: {failed} of {cycles} cycles "
        f"({100 * failed / cycles:.1f}%) fail a compliance check (person speed limit, stop "
        "response, maximum speed, command tracking). The policy slows within 4 m of a person "
        "before the monitor's 0.5 m/s limit applies at 3 m, and the monitor allows braking at "
        "the actuator's rate; so a failed check is an anomaly, not routine."
    )
    out += ["", "Share of cycles that are not CONTINUE, per scenario (min over seeds / mean):", ""]
    out += ["| scenario | min | mean |", "|---|---|---|"]
    for name in SCENARIOS:
        shares = [b.non_continue.get(name, 0.0) for b in clean]
        out.append(f"| {name} | {pct(min(shares))} | {pct(statistics.fmean(shares))} |")
    out += ["", "Safety outcomes against the simulator's ground truth, over the same seeds:", ""]
    out.append(
        "| scenario | min separation to a person | to a vehicle | near-miss events (< 0.5 m) "
        "| stops (changes to STOP) | time to stop, median / max |"
    )
    out.append("|---|---|---|---|---|---|")
    for name in SCENARIOS:
        rows = [b.result.safety[name] for b in clean if name in b.result.safety]
        person = [r["min_separation_person_m"] for r in rows if r["min_separation_person_m"]]
        vehicle = [r["min_separation_vehicle_m"] for r in rows if r["min_separation_vehicle_m"]]
        medians = [r["time_to_stop_median_s"] for r in rows if r["time_to_stop_median_s"]]
        maxes = [r["time_to_stop_max_s"] for r in rows if r["time_to_stop_max_s"]]
        out.append(
            f"| {name} | {_metres(person)} | {_metres(vehicle)} | "
            f"{sum(r['near_miss_events'] for r in rows)} | {sum(r['stops'] for r in rows)} | "
            f"{_seconds(statistics.median(medians) if medians else None)} / "
            f"{_seconds(max(maxes) if maxes else None)} |"
        )
    confusion: dict[str, Counter[str]] = {}
    for b in clean:
        for true, row in b.result.perception["confusion"].items():
            confusion.setdefault(true, Counter()).update(row)
    classes = list(next(iter(confusion.values())))
    out += [
        "",
        "Perception's classification against ground truth (entity-cycles, observed entities "
        "matched to the nearest actor within 1 m; `none`: nothing there):",
        "",
        "| true \\ perceived | " + " | ".join(classes) + " | recall |",
        "|---|" + "---|" * (len(classes) + 1),
    ]
    for true, row in confusion.items():
        total = sum(row.values())
        recall = pct(row[true] / total) if true in classes and total else "—"
        out.append(f"| {true} | " + " | ".join(str(row[c]) for c in classes) + f" | {recall} |")
    precision = []
    for c in classes:
        said = sum(confusion[t][c] for t in confusion)
        precision.append(pct(confusion[c][c] / said) if said else "—")
    out.append("| precision | " + " | ".join(precision) + " | |")
    ex = main.example or {}
    cfs = "; ".join(
        f"would {c['would_select']} if {c['factor']} {c['comparison']} {c['threshold']}"
        for c in ex.get("counterfactuals", [])
    )
    out += [
        "",
        f"**The paper's example** (seed {main.seed}, t = 20.0 s, the worker in front of the "
        f"robot): {ex.get('command')}; {cfs or 'no counterfactual logged'}. Rationale: "
        f'"{ex.get("rationale")}". With the risk below 0.2 the robot would SLOW, not '
        "CONTINUE as in the paper: the worker is within the 4 m slow zone, and cruising past a "
        "person within 3 m breaks the speed limit the compliance monitor checks. The aisle "
        "state is a factor of every decision, so the log shows that the aisle was clear.",
        "",
        f"`trace-sim check-counterfactuals` on this run re-ran {ex.get('replayed')} logged "
        "counterfactuals from the logged belief graphs, each an intervention propagated "
        "through the graph's rules: "
        + ("all hold" if ex.get("replay_ok") else "SOME DO NOT HOLD")
        + f" ({ex.get('unverifiable')} could not be re-run: the previous cycle, whose taken "
        "path sets the policy's hysteresis, was lost to an injected write timeout).",
        "",
        "**What this does to ET, TC and DR.** Every decision names the aisle state as a factor "
        "(it decides the branch a counterfactual takes), so a decision has one more chain to "
        "trace: an injected fault that breaks one chain costs a smaller share of ET(d), which "
        "raises mean ET and ET_partial, while the share of fully traceable decisions, which "
        "any broken chain spoils, does not move beyond seed noise. The longer rationale also "
        "means a rationale cut to half its size (the truncation fault) more often keeps at "
        "least one factor, so fewer decisions have none (ET(d) = 0); DR counts the truncation "
        "itself and does not change. TC depends only on the dropped writes, which the new "
        "policy does not affect.",
        "",
    ]
    return out


def _metres(values: list[float]) -> str:
    return f"{min(values):.2f} m" if values else "—"


def _seconds(value: float | None) -> str:
    return "—" if value is None else f"{value:.1f} s"


def _no_factor_count(report: MetricsReport) -> int:
    return report.overall.no_factors


def _sweep_rows(sweep: list[Run]) -> list[tuple[str, list[float]]]:
    def col(fn: object) -> list[float]:
        return [fn(s.report) for s in sweep]  # type: ignore[operator]

    return [
        ("ET mean", col(lambda r: r.overall.et.mean)),
        ("fully traceable share", col(lambda r: r.overall.fully_traceable_share.mean)),
        ("ET_partial", col(lambda r: r.overall.et_partial.mean)),
        ("TC", col(lambda r: r.overall.tc or 0.0)),
        ("DR", col(lambda r: r.overall.dr or 0.0)),
        ("ET std across decisions", col(lambda r: r.overall.et.std)),
        ("ET std across scenarios", col(lambda r: r.across_groups.et.std)),
    ]


def _causes(report: MetricsReport) -> tuple[dict[str, int], list[float]]:
    """Why decisions are not fully traceable, read from the failure list (the log only)."""
    causes = {
        "no factors named": 0,
        "belief edge missing": 0,
        "evidence ref null": 0,
        "ref does not resolve": 0,
    }
    partial: list[float] = []
    for failure in report.failures:
        problems = [p for p in failure.problems if p.startswith("ET:")]
        if not problems:
            continue
        text = " ".join(problems)
        if "names no factors" in text or "action not logged" in text:
            causes["no factors named"] += 1
            continue
        partial.append(failure.et_partial)
        for key, marker in (
            ("belief edge missing", "belief_path missing"),
            ("evidence ref null", "evidence_ref missing"),
            ("ref does not resolve", "sensor_reading missing"),
        ):
            if marker in text:
                causes[key] += 1
    return causes, partial


def _differences(main: Run, sweep: list[Run]) -> list[str]:
    o = main.report.overall
    across = main.report.across_groups
    assert across is not None
    untraceable = o.decisions - o.fully_traceable
    causes, partial = _causes(main.report)
    named_failing = untraceable - causes["no factors named"]
    cause_text = ", ".join(f"{k}: {v}" for k, v in causes.items())
    mean_partial = statistics.fmean(partial) if partial else math.nan
    paper_et = [float(row[0].rstrip("%")) for row in PAPER_TABLE_III.values()]
    paper_spread = (statistics.pstdev(paper_et), statistics.stdev(paper_et))
    return [
        "**The ± in Table II.** The paper's footnote says its 98.6 ± 7.0 is the std across "
        "the 5 scenarios, but its own Table III puts the five scenario ET values between "
        f"96.4% and 100%, whose std is {paper_spread[0]:.1f} (population) or "
        f"{paper_spread[1]:.1f} (sample) points. A 7-point std fits the spread across "
        f"*decisions* better (ours: {o.et.std * 100:.1f} across decisions, "
        f"{across.et.std * 100:.1f} across scenarios). We print both, each labelled.",
        f"**ET is lower than the paper's.** {untraceable} of {o.decisions} logged decisions "
        "are not fully traceable here, against the paper's 7 of 500. By cause, as the "
        f"failure list reports them (a decision can have several): {cause_text}. "
        f"Leaving out the {causes['no factors named']} decisions whose rationale was "
        f"truncated down to no factors, {named_failing} decisions "
        f"({named_failing / o.decisions * 100:.1f}%) lost a chain to an injected evidence "
        "corruption (3% per entity) or edge write failure (2% per cycle, aimed at an edge "
        "on a factor's chain). With at least one entity on every decision's chains, those "
        "two rates alone put at least 1 - 0.97 x 0.98 = 4.9% of decisions out of full "
        "traceability, not the paper's 1.4%. Decisions whose factors were all truncated "
        "away have no factor to trace: we count ET(d) = 0 for them (a choice, see "
        "metrics.md); over the decisions that do name factors, ET is "
        f"{_et_named(main.report) * 100:.1f}%.",
        "**ET_partial.** The paper quotes 0.98 for the decisions that are not fully "
        "traceable. Ours, over the same kind of decisions (those naming factors), is "
        f"{mean_partial:.2f}: a broken belief edge leaves a factor at depth 1 of 5, a null "
        "ref at 3 of 5, a ref that does not resolve at 4 of 5 (node, belief path, entity, "
        "evidence ref, sensor reading). The paper does not define max_depth closely enough "
        "to match its number; over all decisions our ET_partial is "
        f"{o.et_partial.mean:.3f}.",
        f"**TC.** Ours is {pct(o.tc)}: {o.gaps} gaps from the {o.declared_dropped} cycles the "
        "logger dropped on injected write timeouts (1%), each declared by the next seal, in "
        f"a {o.window_s:.1f} s window. The paper's Table II says 99.0%, but its Table III "
        "has 100% in four scenarios and 99% in the fifth, which average to 99.8%.",
        "**DR.** A decision is not reconstructable when its rationale was truncated (2%), "
        "its counterfactuals timed out (2.5%) or its action is missing. Ours: "
        f"{pct(o.dr)} ({o.not_reconstructable} of {o.decisions}). The paper gives 98.1% but "
        'also "23 of 500 records not fully reconstructable", which is 95.4%; its stated '
        "rates predict about 95.5%. Our figure agrees with its count, not its percentage.",
        "**Time per cycle.** The logger records what it cost the robot's control thread "
        "(`trace.timing` metadata: the time spent in `sensor()`, the four layer calls and "
        "`commit()` up to the hand-over, one cycle in eight timed), and the table quotes it; "
        "that is what the paper's 0.12 ms measures. The simulator's writer is synchronous, so "
        "encoding, sealing and writing are not in that figure; the whole cost of logging, "
        "measured with the logger on and off on the same runs, is in the last section.",
        "**Variance.** A 500-cycle run holds few faulty cycles, so each figure moves by "
        "about a point from seed to seed (table above). Differences of that size, between "
        "the paper and us or between scenarios, are noise; the scenario ranking in the "
        "paper's Table III is not something one 100-cycle run per scenario can establish.",
    ]


def _et_named(report: MetricsReport) -> float:
    o = report.overall
    named = o.decisions - o.no_factors
    return o.et.mean * o.decisions / named if named else math.nan


# The paper's Table II rows for the baselines: "estimates based on architectural capability
# analysis" (its footnote), quoted for comparison only.
PAPER_BASELINES = {
    "attention": {"ET": "20–25", "TC": "70–80", "DR": "N/A", "Time": "<0.01 ms"},
    "SHAP": {"ET": "30–35", "TC": "0", "DR": "N/A", "Time": "0.02 ms"},
    "LIME": {"ET": "25–30", "TC": "0", "DR": "N/A", "Time": "1.29 ms"},
}
BASELINES_TITLE = "## Table II measured: TRACE against LIME, SHAP and attention"


def measure_baselines(seed: int, seeds: int) -> BaselinesReport:
    """``trace-sim baselines`` with more repeats for the timings than its defaults."""
    from evaluation.baselines import BaselinesConfig, run_baselines

    config = BaselinesConfig(
        seed=seed,
        seeds=seeds,
        overhead_repeats=3,
        scaling_cycles=100,
        scaling_repeats=5,
    )
    return run_baselines(config, progress=lambda step: print(step, file=sys.stderr))


def _pm(spread: Spread, scale: float = 100.0, digits: int = 1) -> str:
    return f"{spread.mean * scale:.{digits}f} ± {spread.std * scale:.{digits}f}"


def render_baselines(report: BaselinesReport) -> str:
    """The measured Table II section (methods, cost, scaling, differences)."""
    data = report.as_dict()
    m = report.methods
    cfg = report.config
    seeds = [s.seed for s in report.seeds]
    lines: list[str] = []
    add = lines.append
    add(BASELINES_TITLE)
    add("")
    add(
        f"Measured by `trace-sim baselines` (`evaluation/baselines/`, commit `{git_revision()}`) "
        f"over {len(seeds)} seeds "
        f"({seeds[0]}..{seeds[-1]}), each one run of the paper's evaluation (5 scenarios x "
        f"{cfg.cycles} cycles, faults at the paper's rates). The learned policy (random forest) "
        f"and the attention model were trained on {report.train_decisions} decisions from "
        f"{cfg.train_runs} run(s) with other seeds; on the evaluation runs they agree with the "
        "rule "
        f"policy on {_pm(report.policy_accuracy)}% and {_pm(report.attention_accuracy)}% of "
        f"decisions. Each method explained {cfg.explain_per_seed} randomly drawn decisions per "
        "run; TRACE is scored on every logged decision by `trace_audit.metrics`. Definitions: "
        '[metrics.md](metrics.md), "Explanation baselines" (the metrics written before the '
        "first run; times switched to CPU after it, as it says). "
        "Figures are mean ± std across seeds (population std), in %; times are CPU time."
    )
    add("")
    add(
        "| method | ET paper | ET here | ET_partial here | DR paper | DR here | "
        "time paper | time here (ms) | bytes / decision here |"
    )
    add("|---|---|---|---|---|---|---|---|---|")
    paper_trace = {
        "ET": PAPER_TABLE_II["ET"],
        "DR": PAPER_TABLE_II["DR"],
        "Time": PAPER_TABLE_II["Time"],
    }
    for name in ("TRACE", "LIME", "SHAP", "attention"):
        paper = paper_trace if name == "TRACE" else PAPER_BASELINES[name]
        r = m[name]
        add(
            f"| {name} | {paper['ET']} | {_pm(r.et)} | {_pm(r.et_partial)} | {paper['DR']} | "
            f"{_pm(r.dr)} | {paper['Time']} | {_pm(r.ms_per_decision, 1.0, 3)} | "
            f"{r.bytes_per_decision.mean:,.0f} |"
        )
    add("")
    add(
        "TC is not measured for the baselines: it is a property of how records are kept, not of "
        "an explanation method (metrics.md). The paper's baseline TC (0%, 70–80%) is likewise "
        "an estimate."
    )
    add("")
    o = report.overhead
    add("### TRACE's cost per cycle, logging on and off")
    add("")
    add(
        f"The simulator's whole decision loop over the same {len(seeds)} seeds' scenario runs "
        f"({o.cycles} cycles each, faults off so both sides run identical cycles: same commands "
        f"{'in every cycle' if o.same_commands else 'NOT in every cycle'}), "
        f"{o.runs // len(seeds)} back-to-back repeat(s) per seed, medians; a run's time "
        "includes opening and closing its log, spread over its cycles:"
    )
    add("")
    add("| | CPU us per cycle | wall-clock us per cycle |")
    add("|---|---|---|")
    add(
        "| audit logger on (`AuditLogger`, synchronous, one write per cycle) | "
        f"{o.on_cpu_us:.0f} | {o.on_us:.0f} |"
    )
    add(f"| audit logger off (`NullLogger`) | {o.off_cpu_us:.0f} | {o.off_us:.0f} |")
    add(f"| **overhead** (paper: 120 us) | **{o.overhead_cpu_us:.0f}** | {o.overhead_us:.0f} |")
    add("")
    add("### How the overhead grows with entities n and candidate actions k")
    add("")
    add(
        f"A synthetic decision loop (`evaluation/baselines/cost.py`: n pedestrians with one "
        f"evidence item each, 2 belief nodes per entity, n factors, k-1 alternatives, n x (k-1) "
        f"counterfactuals), {cfg.scaling_cycles} cycles per run, median of "
        f"{cfg.scaling_repeats} back-to-back on/off runs, after {WARM_UP_CYCLES} untimed "
        "cycles; logging overhead in CPU us per cycle, wall-clock after the slash "
        "(compressed bytes per cycle in brackets):"
    )
    add("")
    ks = sorted({p.actions for p in report.scaling})
    ns = sorted({p.entities for p in report.scaling})
    grid = {(p.entities, p.actions): p for p in report.scaling}
    add("| n | " + " | ".join(f"k={k}" for k in ks) + " |")
    add("|---|" + "---|" * len(ks))
    for n in ns:
        cells = [
            f"{grid[n, k].overhead_cpu_us:.0f} / {grid[n, k].overhead_us:.0f} "
            f"({grid[n, k].bytes_per_cycle:,} B)"
            for k in ks
        ]
        add(f"| {n} | " + " | ".join(cells) + " |")
    add("")
    slope_n, slope_k, r2 = _fit(report)
    load = data["machine"]
    add(
        "A least-squares fit of the CPU overhead = a + b n + c k over the grid gives "
        f"b = {slope_n:.1f} "
        f"us per entity and c = {slope_k:.1f} us per action (R² = {r2:.2f})."
    )
    add("")
    add(
        f"Machine: {load['cpus']} cores shared with other work; 1-minute load average "
        f"{load['load_1min_start']} at the start and {load['load_1min_end']} at the end "
        f"of this {load['elapsed_s']:.0f} s measurement. Timings are medians of back-to-back "
        "on/off runs so that load hits both sides alike; CPU time is the figure to compare, "
        "wall-clock time on a loaded machine also holds the waits for a core."
    )
    add("")
    add("### Where the paper's estimates hold, and where not")
    add("")
    for para in _baseline_differences(report, slope_n, slope_k, r2):
        add(para)
        add("")
    return "\n".join(lines)


def _fit(report: BaselinesReport) -> tuple[float, float, float]:
    import numpy as np

    pts = report.scaling
    a = np.array([[1.0, p.entities, p.actions] for p in pts])
    y = np.array([p.overhead_cpu_us for p in pts])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ coef
    total = float(((y - y.mean()) ** 2).sum())
    r2 = 1.0 - float((resid**2).sum()) / total if total else math.nan
    return float(coef[1]), float(coef[2]), r2


def _versus(value: float, low: float, high: float) -> str:
    """Where a measured share stands against the paper's estimated range (both in %)."""
    if value < low:
        return "below the paper's range"
    if value > high:
        return "above the paper's range"
    return "within the paper's range"


def _baseline_differences(
    report: BaselinesReport, slope_n: float, slope_k: float, r2: float
) -> list[str]:
    m = report.methods
    o = report.overhead
    lime, shap, attn, trace = m["LIME"], m["SHAP"], m["attention"], m["TRACE"]

    def share(r: MethodResult) -> str:
        return f"{r.unlinked / r.citations * 100:.0f}%" if r.citations else "n/a"

    shap_vs_lime = (
        "SHAP above LIME, as the paper has it"
        if shap.et.mean > lime.et.mean
        else "SHAP not above LIME, unlike the paper"
    )
    order = sorted(("LIME", "SHAP", "attention"), key=lambda k: m[k].ms_per_decision.mean)
    paper_order = ["attention", "SHAP", "LIME"]
    ranking = (
        "The paper's ranking (attention fastest, LIME slowest) holds"
        if order == paper_order
        else f"The measured ranking ({' < '.join(order)}) differs from the paper's"
    )
    linear = (
        f"a plane in n and k fits the grid with R² = {r2:.2f}"
        if r2 >= 0.8
        else f"a plane in n and k fits the grid only loosely (R² = {r2:.2f}: timing noise)"
    )
    return [
        f"**ET of LIME and SHAP.** Measured {_pm(lime.et)}% "
        f"({_versus(lime.et.mean * 100, 25, 30)}, 25–30%) and {_pm(shap.et)}% "
        f"({_versus(shap.et.mean * 100, 30, 35)}, 30–35%), with {shap_vs_lime}. Both "
        "numbers rest on a choice the paper does not make: this harness stores, with every "
        "explanation, which belief node each input feature was read from. Without that link a "
        'feature attribution names a column ("ped2_risk") that no log message carries, and '
        f"ET is 0 by construction. With it, {share(lime)} of LIME's and {share(shap)} of "
        "SHAP's cited factors still have nothing to follow: they are padding slots (a second "
        "or third pedestrian, or a vehicle, that was not there), which the attributions rank "
        'among the strongest factors because "nobody there" is what let the robot continue. '
        "An absence has no sensor reading; TRACE's rationale only names nodes that exist.",
        f"**ET of attention.** Measured {_pm(attn.et)}%, "
        f"{_versus(attn.et.mean * 100, 20, 25)} (20–25%). Attention weights are over perceived "
        f"entities, so each cited token is an entity node (or the aisle state): {share(attn)} "
        "of its citations lack a node, and its shortfall comes from the same injected evidence "
        "and edge faults that TRACE's chains meet. That is traceability of what was attended "
        "to, not a reason for the decision; and TRACE's ET "
        f"({_pm(trace.et)}%) counts the decisions whose rationale was truncated to nothing as "
        "0, which never happens to an attention record.",
        "**DR.** The paper writes N/A for the baselines. Under the same rule as TRACE's, "
        f"LIME, SHAP and attention score {_pm(lime.dr)}%, {_pm(shap.dr)}% and {_pm(attn.dr)}%: "
        "none produces counterfactuals. Their class probabilities pass as alternatives (they "
        "say nothing of why an alternative lost) and their cited factors as a rationale. "
        f"TRACE: {_pm(trace.dr)}%.",
        f"**Time.** LIME with its default 5000 samples took {_pm(lime.ms_per_decision, 1, 1)} "
        "ms per explanation against the paper's 1.29 ms (the paper gives neither its sample "
        f"count nor its model); SHAP's exact TreeExplainer {_pm(shap.ms_per_decision, 1, 2)} ms "
        "against 0.02 ms; the attention weights cost one numpy forward pass for a single "
        f"decision, {_pm(attn.ms_per_decision, 1, 3)} ms, against <0.01 ms. {ranking}; the "
        "magnitudes depend on a model and settings the paper does not give.",
        f"**TRACE's 0.12 ms.** Measured here: {o.overhead_cpu_us:.0f} us of CPU per cycle "
        f"({o.on_cpu_us:.0f} on, {o.off_cpu_us:.0f} off), {o.overhead_cpu_us / 120:.1f} x "
        f"the paper's 120 us; {o.overhead_us:.0f} us of wall-clock time on this shared "
        "machine. This is the simulator's synchronous configuration: record validation, "
        "canonical encoding, SHA-256 digests of the sensor data and records, the seal and one "
        "MCAP write per cycle, all on the loop thread. The logger's default threaded mode "
        "moves the write off the control thread; `bench/bench_logger.py` measures that cost, "
        "not this section. Against the 100 ms period at 10 Hz the measured overhead is "
        f"{o.overhead_cpu_us / 1000:.2f}% of the cycle in CPU time.",
        f"**Scaling.** The paper says the overhead grows linearly with entities and candidate "
        f"actions. Over n = 1..50 the fit gives {slope_n:.1f} us per entity, over k = 2..8 "
        f"{slope_k:.1f} us per action; {linear}. The paper's O(k²) action-synthesis term "
        "would need larger k to separate from the fixed per-cycle cost.",
        f"**Bytes.** TRACE keeps {trace.bytes_per_decision.mean:,.0f} bytes of canonical JSON "
        "per cycle (before compression) for the whole decision; the baselines keep "
        f"{lime.bytes_per_decision.mean:,.0f} (LIME), {shap.bytes_per_decision.mean:,.0f} "
        f"(SHAP) and {attn.bytes_per_decision.mean:,.0f} (attention) bytes per explanation, "
        "feature-to-node links included. The paper does not compare storage.",
    ]


def replace_section(document: str, section: str) -> str:
    """``document`` with its measured-baselines section (to the next "## " or the end)
    replaced by ``section``, or ``section`` appended when it has none."""
    start = document.find(BASELINES_TITLE)
    if start < 0:
        return document.rstrip("\n") + "\n\n" + section
    end = document.find("\n## ", start + len(BASELINES_TITLE))
    rest = document[end + 1 :] if end >= 0 else ""
    return document[:start] + section.rstrip("\n") + "\n" + ("\n" + rest if rest else "")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=42)
    parser.add_argument("--seeds", type=int, default=20, help="runs for the variance table")
    parser.add_argument(
        "--baseline-seeds", type=int, default=10, help="runs for the measured Table II (>= 5)"
    )
    parser.add_argument(
        "--baselines-only",
        action="store_true",
        help="measure only the baselines and replace that section of --out, keeping the rest",
    )
    parser.add_argument(
        "--out", type=Path, default=Path(__file__).resolve().parents[1] / "docs" / "reproduction.md"
    )
    args = parser.parse_args()
    baselines = render_baselines(measure_baselines(1, args.baseline_seeds))
    if args.baselines_only:
        text = replace_section(args.out.read_text(), baselines)
    else:
        seeds = list(range(1, args.seeds + 1))
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp)
            main_run = simulate(args.seed, work)
            sweep = [simulate(seed, work) for seed in seeds]
            clean = [behave(seed, work) for seed in range(1, 11)]
        text = render(main_run, sweep, seeds, clean).rstrip("\n") + "\n\n" + baselines
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(text)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
