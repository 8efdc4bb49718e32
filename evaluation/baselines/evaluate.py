"""``trace-sim baselines``: TRACE against LIME, SHAP and attention on the same runs.

For each evaluation seed: simulate the paper's run (5 scenarios x ``cycles``, faults at the
paper's rates), score TRACE with ``trace_audit.metrics.compute_metrics`` on the log, then
read the log back, let the learned policy and the attention model decide every logged
cycle, explain a sample of those decisions with each method and score every explanation
against the same logged cycle (``scoring``). The models are trained beforehand on runs with
other seeds. Then TRACE's per-cycle cost (``cost``). Figures are per seed, then mean and
std across seeds.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.baselines.cost import Overhead, ScalingPoint, measure_overhead, measure_scaling
from evaluation.baselines.explain import METHODS, Explainers, train_explainers
from evaluation.baselines.features import DecisionInput, read_decision_input
from evaluation.baselines.scoring import ExplanationScore, score_explanation
from sim.faults import FaultRates
from sim.runner import RunConfig, SimUsageError, run
from trace_audit.chains import DEFAULT_SENSOR_WINDOW, SensorWindow
from trace_audit.metrics import MetricsConfig, compute_metrics
from trace_runtime import open_log
from trace_runtime.records import (
    LAYER_TOPICS,
    TOPIC_ACTION,
    TOPIC_BELIEF,
    TOPIC_PERCEPTION,
    TOPIC_SEAL,
)

__all__ = [
    "BaselinesConfig",
    "BaselinesReport",
    "MethodResult",
    "SeedResult",
    "run_baselines",
]

ProgressCallback = Callable[[str], None]
TRAIN_SEED_OFFSET = 10_000
"""Training runs use seeds far from the evaluation seeds, so no run is in both sets."""


@dataclass(frozen=True, slots=True)
class BaselinesConfig:
    """What ``run_baselines`` measures; the defaults finish in well under two minutes."""

    seed: int = 1
    """First evaluation seed; the others follow it."""
    seeds: int = 5
    cycles: int = 100
    """Decision cycles per scenario and run (the paper: 100)."""
    train_runs: int = 2
    explain_per_seed: int = 100
    """Decisions explained per seed by each method (a random sample of the logged ones)."""
    overhead_repeats: int = 2
    scaling_entities: tuple[int, ...] = (1, 2, 5, 10, 20, 50)
    scaling_actions: tuple[int, ...] = (2, 4, 6, 8)
    scaling_cycles: int = 40
    scaling_repeats: int = 3

    def __post_init__(self) -> None:
        for name in ("seeds", "cycles", "train_runs", "explain_per_seed", "scaling_cycles"):
            if getattr(self, name) < 1:
                raise SimUsageError(f"{name.replace('_', ' ')} must be at least 1")
        if self.seed < 0:
            raise SimUsageError(f"seed must be >= 0, got {self.seed}")

    @property
    def eval_seeds(self) -> list[int]:
        return [self.seed + i for i in range(self.seeds)]

    @property
    def train_seeds(self) -> list[int]:
        return [self.seed + TRAIN_SEED_OFFSET + i for i in range(self.train_runs)]


@dataclass(frozen=True, slots=True)
class MethodSeed:
    """One method's figures on one seed's run."""

    et: float
    et_partial: float
    dr: float
    ms_per_decision: float
    bytes_per_decision: float
    decisions: int
    citations: int
    """Factors cited (TRACE: named) over those decisions."""
    unlinked: int
    """Cited factors with no node of the cycle's belief graph to follow."""


@dataclass(frozen=True, slots=True)
class SeedResult:
    seed: int
    decisions: int
    policy_accuracy: float
    attention_accuracy: float
    methods: dict[str, MethodSeed]
    problems: dict[str, dict[str, int]]
    """Per method: how often each kind of shortfall was seen on the explained decisions."""


@dataclass(frozen=True, slots=True)
class Spread:
    mean: float
    std: float
    """Population std across seeds."""
    low: float
    high: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Spread:
        return cls(
            statistics.fmean(values),
            statistics.pstdev(values) if len(values) > 1 else 0.0,
            min(values),
            max(values),
        )


@dataclass(frozen=True, slots=True)
class MethodResult:
    et: Spread
    et_partial: Spread
    dr: Spread
    ms_per_decision: Spread
    bytes_per_decision: Spread
    decisions: int
    citations: int
    unlinked: int


@dataclass(frozen=True, slots=True)
class BaselinesReport:
    config: BaselinesConfig
    methods: dict[str, MethodResult]
    overhead: Overhead
    scaling: list[ScalingPoint]
    policy_accuracy: Spread
    attention_accuracy: Spread
    seeds: list[SeedResult] = field(default_factory=list)
    train_decisions: int = 0
    load: tuple[float, float] = (0.0, 0.0)
    """1-minute load average of the machine when the run started and when it ended: other
    processes share the cores, and the timings move with them."""
    elapsed_s: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        """The JSON of ``trace-sim baselines --json``."""

        methods = {name: _method_dict(m) for name, m in self.methods.items()}
        return {
            "methods": methods,
            "overhead": _overhead_dict(self.overhead),
            "scaling": [_scaling_dict(p) for p in self.scaling],
            "policy_accuracy": round(self.policy_accuracy.mean, 4),
            "attention_accuracy": round(self.attention_accuracy.mean, 4),
            "seeds": [s.seed for s in self.seeds],
            "train_decisions": self.train_decisions,
            "machine": {
                "cpus": os.cpu_count(),
                "load_1min_start": round(self.load[0], 2),
                "load_1min_end": round(self.load[1], 2),
                "elapsed_s": round(self.elapsed_s, 1),
            },
            "problems": {
                name: _sum_counts(s.problems.get(name, {}) for s in self.seeds)
                for name in ("TRACE", *METHODS)
            },
        }


def _spread(s: Spread, digits: int = 4) -> dict[str, float]:
    return {k: round(v, digits) for k, v in vars_of(s).items()}


def _method_dict(m: MethodResult) -> dict[str, Any]:
    """One method's row of the JSON: means over seeds, and their spread."""
    return {
        "ET": round(m.et.mean, 4),
        "ET_partial": round(m.et_partial.mean, 4),
        "DR": round(m.dr.mean, 4),
        "ms_per_decision": round(m.ms_per_decision.mean, 4),
        "bytes_per_decision": round(m.bytes_per_decision.mean, 1),
        "decisions": m.decisions,
        "cited_factors": m.citations,
        "cited_without_link": m.unlinked,
        "spread_over_seeds": {
            "ET": _spread(m.et),
            "ET_partial": _spread(m.et_partial),
            "DR": _spread(m.dr),
            "ms_per_decision": _spread(m.ms_per_decision),
            "bytes_per_decision": _spread(m.bytes_per_decision, 1),
        },
    }


def _overhead_dict(o: Overhead) -> dict[str, Any]:
    """TRACE's cost per cycle on the paper's runs, logger on and off."""
    return {
        "on_us": round(o.on_us, 1),
        "off_us": round(o.off_us, 1),
        "overhead_us": round(o.overhead_us, 1),
        "on_cpu_us": round(o.on_cpu_us, 1),
        "off_cpu_us": round(o.off_cpu_us, 1),
        "overhead_cpu_us": round(o.overhead_cpu_us, 1),
        "cycles_per_run": o.cycles,
        "runs_per_side": o.runs,
        "same_commands": o.same_commands,
    }


def _scaling_dict(p: ScalingPoint) -> dict[str, Any]:
    """TRACE's cost per cycle with ``p.entities`` entities and ``p.actions`` actions."""
    return {
        "entities": p.entities,
        "actions": p.actions,
        "on_us": round(p.on_us, 1),
        "off_us": round(p.off_us, 1),
        "overhead_us": round(p.overhead_us, 1),
        "on_cpu_us": round(p.on_cpu_us, 1),
        "off_cpu_us": round(p.off_cpu_us, 1),
        "overhead_cpu_us": round(p.overhead_cpu_us, 1),
        "bytes_per_cycle": p.bytes_per_cycle,
    }


def vars_of(s: Spread) -> dict[str, float]:
    return {"mean": s.mean, "std": s.std, "min": s.low, "max": s.high}


def _sum_counts(counts: Any) -> dict[str, int]:
    total: dict[str, int] = {}
    for c in counts:
        for k, v in c.items():
            total[k] = total.get(k, 0) + v
    return dict(sorted(total.items(), key=lambda kv: -kv[1]))


def _simulate(seed: int, cycles: int, workdir: Path) -> Path:
    out = workdir / f"run-{seed}.mcap"
    run(RunConfig(out=out, cycles=cycles, seed=seed, faults=FaultRates()))
    return out


def read_inputs(log_path: Path) -> list[DecisionInput]:
    """The baselines' view of every logged decision of a log."""
    found = []
    for cycle in open_log(log_path).iter_cycles():
        d = read_decision_input(
            cycle.cycle, cycle.t_ns, cycle.layer(TOPIC_ACTION), cycle.layer(TOPIC_BELIEF)
        )
        if d is not None:
            found.append(d)
    return found


def _problem_kind(problem: str) -> str:
    """'ET: ped2_risk: factor_node missing (...)' -> 'ET: factor_node missing'."""
    head, _, rest = problem.partition(": ")
    if head == "ET" and ": " in rest:
        rest = rest.split(": ", 1)[1]
    return f"{head}: {rest.split(' (', 1)[0]}"


def _score_seed(
    seed: int, log_path: Path, explainers: Explainers, sample: int, trace_ms: float
) -> SeedResult:
    inputs = read_inputs(log_path)
    rng = np.random.default_rng(seed)
    chosen = {
        inputs[i].cycle
        for i in rng.choice(len(inputs), size=min(sample, len(inputs)), replace=False)
    }
    by_cycle = {d.cycle: d for d in inputs}
    scores: dict[str, list[ExplanationScore]] = {m: [] for m in METHODS}
    seconds: dict[str, list[float]] = {m: [] for m in METHODS}
    problems: dict[str, dict[str, int]] = {m: {} for m in METHODS}
    window = SensorWindow(DEFAULT_SENSOR_WINDOW)
    trace_bytes: list[int] = []
    for cycle in open_log(log_path).iter_cycles():
        window.push(cycle.sensors)
        trace_bytes.append(
            sum(len(cycle.payloads.get(t, b"")) for t in (*LAYER_TOPICS, TOPIC_SEAL))
        )
        d = by_cycle.get(cycle.cycle) if cycle.cycle in chosen else None
        if d is None:
            continue
        belief, perception = cycle.layer(TOPIC_BELIEF), cycle.layer(TOPIC_PERCEPTION)
        for record in explainers.explain(d):
            score = score_explanation(record, belief, perception, window)
            scores[record.method].append(score)
            seconds[record.method].append(record.seconds)
            for p in score.problems:
                kind = _problem_kind(p)
                problems[record.method][kind] = problems[record.method].get(kind, 0) + 1
    trace, trace_problems = _trace_seed(log_path, trace_bytes, trace_ms)
    methods = {"TRACE": trace}
    for m in METHODS:
        methods[m] = _method_seed(scores[m], seconds[m], problems[m])
    return SeedResult(
        seed=seed,
        decisions=len(inputs),
        policy_accuracy=explainers.learned_accuracy(inputs),
        attention_accuracy=explainers.attention_accuracy(inputs),
        methods=methods,
        problems={"TRACE": trace_problems, **problems},
    )


def _trace_seed(
    log_path: Path, trace_bytes: list[int], trace_ms: float
) -> tuple[MethodSeed, dict[str, int]]:
    """TRACE's figures on one run, by the investigator's metrics, and its problems by kind."""
    report = compute_metrics([log_path], MetricsConfig(max_listed=10_000))
    o = report.overall
    trace_problems: dict[str, int] = {}
    for failure in report.failures:
        for p in failure.problems:
            kind = _problem_kind(p)
            trace_problems[kind] = trace_problems.get(kind, 0) + 1
    # the simulator cites no external recording, so no decision's ET is unknown
    assert o.et.mean is not None and o.et_partial.mean is not None
    trace = MethodSeed(
        et=o.et.mean,
        et_partial=o.et_partial.mean,
        dr=o.dr if o.dr is not None else 0.0,
        ms_per_decision=trace_ms,
        bytes_per_decision=statistics.fmean(trace_bytes),
        decisions=o.decisions,
        citations=o.factors,
        unlinked=trace_problems.get("ET: factor_node missing", 0),
    )
    return trace, trace_problems


def _method_seed(
    got: list[ExplanationScore], seconds: list[float], problems: dict[str, int]
) -> MethodSeed:
    """A baseline's figures on one run, from its scored explanations."""
    return MethodSeed(
        et=statistics.fmean(s.et for s in got),
        et_partial=statistics.fmean(s.et_partial for s in got),
        dr=statistics.fmean(float(s.dr) for s in got),
        ms_per_decision=statistics.median(seconds) * 1e3,
        bytes_per_decision=statistics.fmean(s.bytes for s in got),
        decisions=len(got),
        citations=sum(s.citations for s in got),
        unlinked=problems.get("ET: factor_node missing", 0),
    )


def run_baselines(
    config: BaselinesConfig | None = None, progress: ProgressCallback | None = None
) -> BaselinesReport:
    """Measure TRACE, LIME, SHAP and attention on the same runs; TRACE's cost on and off."""
    cfg = config or BaselinesConfig()
    started = time.perf_counter()
    load_start = os.getloadavg()[0]

    def say(step: str) -> None:
        if progress is not None:
            progress(step)

    with tempfile.TemporaryDirectory(prefix="trace-baselines-") as tmp:
        work = Path(tmp)
        say("training the learned policy and the attention model")
        train: list[DecisionInput] = []
        for seed in cfg.train_seeds:
            train += read_inputs(_simulate(seed, cfg.cycles, work))
        explainers = train_explainers(train, cfg.seed)
        say("measuring TRACE's cost per cycle, logging on and off")
        overhead = measure_overhead(cfg.eval_seeds, cfg.cycles, work, cfg.overhead_repeats)
        seeds = []
        for seed in cfg.eval_seeds:
            on, off = overhead.per_seed[seed]  # CPU us, like the explainers' times
            say(f"seed {seed}: simulating, explaining, scoring")
            seeds.append(
                _score_seed(
                    seed, _simulate(seed, cfg.cycles, work), explainers,
                    cfg.explain_per_seed, (on - off) / 1e3,
                )
            )  # fmt: skip
    say("scaling with entities and candidate actions")
    scaling = measure_scaling(
        cfg.scaling_entities, cfg.scaling_actions, cfg.scaling_cycles, cfg.scaling_repeats
    )
    methods = {}
    for name in ("TRACE", *METHODS):
        per = [s.methods[name] for s in seeds]
        methods[name] = MethodResult(
            et=Spread.of([p.et for p in per]),
            et_partial=Spread.of([p.et_partial for p in per]),
            dr=Spread.of([p.dr for p in per]),
            ms_per_decision=Spread.of([p.ms_per_decision for p in per]),
            bytes_per_decision=Spread.of([p.bytes_per_decision for p in per]),
            decisions=sum(p.decisions for p in per),
            citations=sum(p.citations for p in per),
            unlinked=sum(p.unlinked for p in per),
        )
    return BaselinesReport(
        config=cfg,
        methods=methods,
        overhead=overhead,
        scaling=scaling,
        policy_accuracy=Spread.of([s.policy_accuracy for s in seeds]),
        attention_accuracy=Spread.of([s.attention_accuracy for s in seeds]),
        seeds=seeds,
        train_decisions=len(train),
        load=(load_start, os.getloadavg()[0]),
        elapsed_s=time.perf_counter() - started,
    )
