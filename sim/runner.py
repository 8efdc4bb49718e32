"""Run the simulator: world -> sensors -> the four layers -> ``trace_runtime`` log.

``run(RunConfig(...))`` is the library entry point; the CLI only parses and renders.
"""

from __future__ import annotations

import gc
import re
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import numpy as np

from sim.belief import BeliefGraph, Edge, build_belief
from sim.counterfactual import BudgetExhaustedError, probe
from sim.decision import Decider, Decision, graph_edges
from sim.execution import Actuator, Executed, Steering
from sim.faults import (
    DEFAULT_ROBOT_ID,
    CycleFaults,
    FailingOpener,
    FaultInjector,
    FaultRates,
    TruthLog,
    truth_path_for,
)
from sim.nulllog import NullLogger
from sim.perception import CORRIDOR_MAX_M, Perceiver, PerceptionOutput
from sim.quality import QualityMeter
from sim.records import (
    RationaleBuffer,
    action_record,
    belief_record,
    counterfactual_records,
    cut_edges,
    entities_under,
    execution_record,
    perception_record,
    rationale_size,
    reaches_entity,
    write_rationale,
)
from sim.scenarios import EPISODE_CYCLES, SCENARIOS
from sim.sensors import detect_camera, range_ultrasonic, scan_lidar
from sim.world import PERIOD_S, World
from trace_runtime import AuditLogger, LoggerConfig, TraceError
from trace_runtime.clock import EARLIEST_WALL_NS
from trace_runtime.errors import UsageError
from trace_runtime.flags import SCENARIO_FLAG

PERIOD_NS = 100_000_000
CYCLES_PER_DAY = 864_000
SOFTWARE_VERSION = "trace-sim 0.1"
POLICY_VERSION = "fig2-v2"
"""v2: speed limit near people in the tree, hysteresis, counterfactuals as interventions."""
TIMEOUT_BUDGET = 2
"""Probe budget (policy evaluations) left when a counterfactual timeout is injected."""
DURATION_BATCH = 50
"""Cycles per write that ``trace-sim run --duration`` uses unless told otherwise."""
EPISODE_ROOM_M = 28.0
"""Straight aisle an episode needs ahead: the farthest spawn (~15 m) plus 10 s of driving."""


class SimError(TraceError):
    """Base of the simulator's own errors (a ``TraceError``, the project's one error root)."""


class SimUsageError(SimError, ValueError):
    """A bad option: unknown scenario, non-positive cycle count, bad rate."""


class SimOutputError(SimError):
    """The output path cannot be written."""


@dataclass(frozen=True, slots=True)
class RunConfig:
    """What to simulate and where to log it."""

    out: Path
    scenario: str = "all"
    cycles: int = 100
    """Cycles per scenario (``all`` runs each scenario this many cycles, in order)."""
    seed: int = 0
    faults: FaultRates = field(default_factory=FaultRates)
    total_cycles: int | None = None
    """Routine operation: this many cycles, cycling through the scenarios episode by episode."""
    robot_id: str = DEFAULT_ROBOT_ID
    start_ns: int = 0
    """The first cycle's time: ns on ``clock`` (``parse_start``)."""
    clock: str = "sim"
    """The segments' session ``clock``: ``sim`` (counting from an arbitrary zero) or
    ``system`` (``start_ns`` is then ns since the Unix epoch, a time of day)."""
    batch_cycles: int = 1
    """Cycles per write (``LoggerConfig.batch_cycles``). 1 for the paper's runs: an injected
    audit-write timeout then loses exactly one cycle. Above 1 (long generated runs) every
    write carries that many cycles, and a timed-out write loses all of them (see ``faults``)."""
    audit: bool = True
    """False: the same loop with a ``NullLogger`` (nothing written), to measure what logging
    costs per cycle. The ground-truth sidecar is still written."""
    checkpoint_key: Path | None = None
    """The robot's private key file: checkpoints signed (``LoggerConfig.checkpoint_key``)."""
    witness: str | None = None
    """A witness's URL the logger submits each checkpoint to (``LoggerConfig.witness``)."""


@dataclass(frozen=True, slots=True)
class RunResult:
    """What a run did."""

    out: Path
    truth: Path
    segments: tuple[Path, ...]
    cycles: int
    written: int
    dropped: int
    commands: dict[str, int]
    scenarios: dict[str, int]
    faults: dict[str, int]
    bytes_written: int
    elapsed_s: float
    seed: int
    batch_cycles: int = 1
    perception: dict[str, Any] = field(default_factory=dict)
    """Classification quality against the world's ground truth (``sim.quality``)."""
    safety: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Safety outcomes per scenario against the world's ground truth (``sim.quality``)."""

    @property
    def cycles_per_s(self) -> float:
        return self.cycles / self.elapsed_s if self.elapsed_s > 0 else float("inf")

    def as_dict(self) -> dict[str, Any]:
        return {
            "out": str(self.out),
            "truth": str(self.truth),
            "segments": [str(p) for p in self.segments],
            "cycles": self.cycles,
            "written": self.written,
            "dropped": self.dropped,
            "commands": self.commands,
            "scenarios": self.scenarios,
            "faults": self.faults,
            "bytes_written": self.bytes_written,
            "elapsed_s": round(self.elapsed_s, 3),
            "cycles_per_s": round(self.cycles_per_s, 1),
            "seed": self.seed,
            "batch_cycles": self.batch_cycles,
            "perception": self.perception,
            "safety": self.safety,
        }


def parse_duration(text: str) -> int:
    """``24h`` / ``90m`` / ``30s`` / ``1d`` -> number of 10 Hz cycles."""
    units = {"s": 1, "m": 60, "h": 3600, "d": 86400}
    t = text.strip().lower()
    try:
        seconds = float(t[:-1]) * units[t[-1]] if t and t[-1] in units else float(t)
    except ValueError as err:
        raise SimUsageError(f"bad duration {text!r}: use e.g. 24h, 90m, 30s") from err
    if seconds <= 0:
        raise SimUsageError(f"duration must be positive: {text!r}")
    return max(1, round(seconds / PERIOD_S))


_ISO = re.compile(r"\d{4}-\d{2}-\d{2}T.*")


def parse_start(text: str) -> tuple[int, str]:
    """``--start`` -> (first cycle's time in ns, session clock).

    An ISO 8601 time with a zone (``2026-05-04T06:00:00Z``) starts a wall clock
    (``system``, ns since the Unix epoch); seconds (``3600``, ``0.5``) a sim clock there."""
    t = text.strip()
    if _ISO.fullmatch(t):
        try:
            moment = datetime.fromisoformat(t)
        except ValueError as err:
            raise SimUsageError(f"bad --start {text!r}: {err}") from err
        if moment.tzinfo is None:
            raise SimUsageError(f"--start {text!r} needs a zone, e.g. Z for UTC")
        delta = moment.astimezone(UTC) - datetime(1970, 1, 1, tzinfo=UTC)
        ns = (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
        if ns < EARLIEST_WALL_NS:
            # Readers take a system clock before 2000 for one counting from zero
            # (trace_runtime.clock.is_wall_clock): it would not be shown as a time of day.
            raise SimUsageError(f"--start {text!r} is before 2000; give seconds for a sim clock")
        return ns, "system"
    try:
        seconds = Decimal(t)
    except InvalidOperation as err:
        raise SimUsageError(
            f"bad --start {text!r}: give seconds (e.g. 3600) or an ISO 8601 UTC time "
            "(e.g. 2026-05-04T06:00:00Z)"
        ) from err
    if not seconds.is_finite() or seconds < 0:
        raise SimUsageError(f"--start must be seconds >= 0, got {text!r}")
    return int(seconds * 1_000_000_000), "sim"


def plan(config: RunConfig) -> Iterator[tuple[str, bool]]:
    """(scenario, starts a new episode) for each cycle of the run."""
    if config.total_cycles is not None:
        names = list(SCENARIOS)
        for k in range(config.total_cycles):
            episode, offset = divmod(k, EPISODE_CYCLES)
            yield names[episode % len(names)], offset == 0
        return
    names = list(SCENARIOS) if config.scenario == "all" else [config.scenario]
    for name in names:
        for k in range(config.cycles):
            yield name, k % EPISODE_CYCLES == 0


def _validate(config: RunConfig) -> int:
    if config.batch_cycles < 1:
        raise SimUsageError(f"batch cycles must be at least 1, got {config.batch_cycles}")
    if config.start_ns < 0:
        raise SimUsageError(f"the start time must be >= 0 ns, got {config.start_ns}")
    if config.total_cycles is not None:
        if config.total_cycles <= 0:
            raise SimUsageError("total cycles must be positive")
        return config.total_cycles
    if config.scenario != "all" and config.scenario not in SCENARIOS:
        known = ", ".join(["all", *SCENARIOS])
        raise SimUsageError(f"unknown scenario {config.scenario!r} (known: {known})")
    if config.cycles <= 0:
        raise SimUsageError(f"cycles must be positive, got {config.cycles}")
    for name, rate in config.faults.as_dict().items():
        if not 0.0 <= rate <= 1.0:
            raise SimUsageError(f"fault rate {name} must be in [0, 1], got {rate}")
    return config.cycles * (len(SCENARIOS) if config.scenario == "all" else 1)


def run(config: RunConfig, progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Simulate and log; ``progress(done, total)`` is called every 1000 cycles and at the end."""
    total = _validate(config)
    out = Path(config.out)
    truth_path = truth_path_for(out, config.robot_id)
    opener = FailingOpener()
    truth, logger = _open_outputs(config, out, truth_path, opener)
    sim = _Pipeline(config, logger, opener, truth)
    commands: dict[str, int] = {}
    per_scenario: dict[str, int] = {}
    started = time.perf_counter()
    done = 0
    try:
        with few_collections():
            for k, (scenario, new_episode) in enumerate(plan(config)):
                if new_episode:
                    sim.world.make_room(EPISODE_ROOM_M)
                    sim.world.actors = SCENARIOS[scenario].spawn(sim.world)
                command = sim.cycle(scenario, config.start_ns + k * PERIOD_NS)
                commands[command] = commands.get(command, 0) + 1
                per_scenario[scenario] = per_scenario.get(scenario, 0) + 1
                done += 1
                if progress is not None and done % 1000 == 0:
                    progress(done, total)
    finally:
        try:
            logger.close()  # writes the last, partial batch
            sim.settle()
        finally:
            truth.close()
    elapsed = time.perf_counter() - started
    if progress is not None:
        progress(done, total)
    stats = logger.stats
    return RunResult(
        out=out,
        truth=truth_path,
        segments=tuple(stats.segments),
        cycles=done,
        written=stats.written,
        dropped=stats.dropped,
        commands=commands,
        scenarios=per_scenario,
        faults=dict(truth.counts),
        bytes_written=stats.bytes_written,
        elapsed_s=elapsed,
        seed=config.seed,
        batch_cycles=config.batch_cycles,
        perception=sim.quality.perception(),
        safety=sim.quality.outcomes(),
    )


def _open_outputs(
    config: RunConfig, out: Path, truth_path: Path, opener: FailingOpener
) -> tuple[TruthLog, AuditLogger | NullLogger]:
    """The ground-truth sidecar and the logger (a null one when ``config.audit`` is off)."""
    try:
        if out.suffix == ".mcap":
            out.parent.mkdir(parents=True, exist_ok=True)
        else:
            out.mkdir(parents=True, exist_ok=True)
        # The logger first: it refuses a bad robot id before the truth file (named by it)
        # is made.
        logger: AuditLogger | NullLogger = (
            NullLogger()
            if not config.audit
            else AuditLogger(
                out,
                robot_id=config.robot_id,
                period_s=PERIOD_S,
                software_version=SOFTWARE_VERSION,
                policy_version=POLICY_VERSION,
                clock=config.clock,
                config=LoggerConfig(
                    threaded=False,
                    fsync_interval_s=None,
                    opener=opener,
                    batch_cycles=config.batch_cycles,
                    checkpoint_key=config.checkpoint_key,
                    witness=config.witness,
                ),
            )
        )
    except UsageError as err:
        raise SimUsageError(str(err)) from err
    except OSError as err:
        raise SimOutputError(f"cannot write {out}: {err.strerror or err}") from err
    except TraceError as err:
        raise SimOutputError(f"cannot write {out}: {err}") from err
    try:
        truth = TruthLog(truth_path, keep=out.suffix != ".mcap")
    except OSError as err:
        logger.close()
        raise SimOutputError(f"cannot write {truth_path}: {err.strerror or err}") from err
    return truth, logger


@contextmanager
def few_collections() -> Iterator[None]:
    """Keep the cyclic garbage collector from re-scanning the same objects over and over.

    A batch of cycles keeps thousands of record objects alive until it is written; with the
    default thresholds that alone triggers a collection every few cycles, each walking every
    object the process has ever imported (measured: ~70 us per cycle at 50 cycles a batch).
    The simulator makes little cyclic garbage, so: freeze what exists, collect rarely.
    """
    threshold = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(max(threshold[0], 50_000), threshold[1], threshold[2])
    try:
        yield
    finally:
        gc.set_threshold(*threshold)
        gc.unfreeze()


Pending = list[tuple[str, dict[str, Any]]]


def _execution_flags(
    scenario: str, executed: Executed, seen: PerceptionOutput, steering: Steering
) -> list[str]:
    """The execution record's flags: the scenario label, then what went wrong or is special."""
    flags = [SCENARIO_FLAG + scenario]
    if any(not ch.passed for ch in executed.checks):
        flags.append("compliance_violation")
    if seen.sensors_unavailable:
        flags.append("sensor_degraded")
    if steering.turning_from is not None:
        # The executive is completing a U-turn that a REROUTE began, whatever
        # this cycle's command: the intended motion above is that turn.
        flags.append("u_turn")
    return flags


@dataclass(slots=True)
class _Unsettled:
    """A committed cycle whose write outcome (and so whose ground truth) is not known yet."""

    cycle: int
    t_ns: int
    scenario: str
    write_timeout: bool
    pending: Pending


class _Pipeline:
    """The robot: world, sensors, the four layers and the logger, one cycle at a time."""

    def __init__(
        self,
        config: RunConfig,
        logger: AuditLogger | NullLogger,
        opener: FailingOpener,
        truth: TruthLog,
    ) -> None:
        seeds = np.random.SeedSequence(config.seed).spawn(4)
        self.world = World(np.random.default_rng(seeds[0]))
        self.sensor_rng = np.random.default_rng(seeds[1])
        self.injector = FaultInjector(config.faults, np.random.default_rng(seeds[2]))
        self.actuator = Actuator(np.random.default_rng(seeds[3]))
        self.steering = Steering()
        self.quality = QualityMeter()
        self.perceiver = Perceiver()
        self.decider = Decider()
        self.logger = logger
        self.opener = opener
        self.truth = truth
        self._unsettled: list[_Unsettled] = []
        self._held: str | None = None  # the leaf taken last cycle (the policy's hysteresis)
        self._written = 0
        self._dropped = 0

    def cycle(self, scenario: str, t_ns: int) -> str:
        """One decision cycle through the four layers, logged; then the world moves on."""
        world, actuator = self.world, self.actuator
        logger, opener = self.logger, self.opener
        faults = self.injector.draw_cycle()
        pending: Pending = []
        pose = world.robot_pose()
        scan = scan_lidar(world, self.sensor_rng)
        detections = (
            None if faults.camera_down else detect_camera(world, scan.truth, self.sensor_rng)
        )
        us_range = range_ultrasonic(scan.truth, self.sensor_rng)
        for sensor, down in (("lidar", faults.lidar_down), ("camera", faults.camera_down)):
            if down:
                pending.append(("sensor_unavailable", {"sensor": sensor}))
        corridor_len = min(
            CORRIDOR_MAX_M, world.route.to_end(world.robot.s, world.robot.direction) + 1.0
        )
        # The injected timeout fails whatever write this cycle's commit makes: the cycle's own
        # (one cycle per write), or with batching the batch it completes; else nothing.
        opener.set_failing(faults.write_timeout)
        try:
            with logger.cycle(t_ns) as c:
                cycle_no = c.cycle
                # Layer 1: sensors -> entities; the readings used are logged as they are read.
                seen = self.perceiver.step(
                    cycle=cycle_no,
                    pose=pose,
                    speed=actuator.linear,
                    scan=None if faults.lidar_down else scan,
                    detections=detections,
                    us_range=us_range,
                    corridor_length=corridor_len,
                    log_sensor=c.sensor,
                )
                # Layer 2
                graph = build_belief(seen, pose, actuator.linear)
                # Layer 3
                decision, action = self._decide(graph, faults, pending)
                outcome = decision.outcome
                # Layer 4
                executed = self._act(outcome.command, graph)
                flags = _execution_flags(scenario, executed, seen, self.steering)
                logged_factors = [f["node"] for f in action["rationale"]["factors"]]
                corrupt, skip = self._audit_faults(
                    seen, graph, decision.factors, logged_factors, faults, pending
                )
                action["parameters"] = {
                    "linear": executed.intended[0],
                    "angular": executed.intended[1],
                }
                c.perception(perception_record(seen, pose, corrupt))
                c.belief(belief_record(graph, skip))
                c.action(action)
                c.execution(execution_record(executed, flags))
        finally:
            opener.set_failing(False)
        self._unsettled.append(_Unsettled(cycle_no, t_ns, scenario, faults.write_timeout, pending))
        self.settle()
        self._held = outcome.path[-1]
        self.quality.observe(world, seen, scenario, outcome.command, actuator.linear)
        world.apply_motion(actuator.linear, actuator.angular)
        world.step_actors()
        return outcome.command

    def _act(self, command: str, graph: BeliefGraph) -> Executed:
        """Layer 4: steer ``command`` along the route and drive the actuator one period."""
        world = self.world
        heading_error, lateral = world.robot.offsets()
        want = self.steering.steer(
            command,
            heading_error=heading_error,
            lateral=lateral,
            direction=world.robot.direction,
        )
        return self.actuator.step(command, world.t, graph, want)

    def settle(self) -> None:
        """Record the ground truth of cycles whose write has happened (written or lost)."""
        stats = self.logger.stats
        lost_io = stats.dropped_io + stats.dropped_queue_full  # not aborts: never handed over
        written, dropped = stats.written - self._written, lost_io - self._dropped
        if not written and not dropped:
            return
        self._written, self._dropped = stats.written, lost_io
        # The synchronous logger makes at most one write per commit (and one at close), and a
        # write keeps or loses its whole batch: so this is one batch, the oldest cycles.
        n = written + dropped
        batch, self._unsettled = self._unsettled[:n], self._unsettled[n:]
        if dropped:
            # The whole batch (its sensor messages too) is gone: nothing else of it is logged.
            kind = "audit_write_timeout" if batch[-1].write_timeout else "audit_write_failed"
            detail: dict[str, Any] = {"dropped": True}
            if len(batch) > 1:
                detail["batch"] = [batch[0].cycle, batch[-1].cycle]
            for u in batch:
                self.perceiver.forget_cycle(u.cycle)
                self.truth.write(u.cycle, u.t_ns, u.scenario, kind, detail)
            return
        for u in batch:
            for kind, detail in u.pending:
                self.truth.write(u.cycle, u.t_ns, u.scenario, kind, detail)

    def _decide(
        self, graph: BeliefGraph, faults: CycleFaults, pending: Pending
    ) -> tuple[Decision, dict[str, Any]]:
        """Layer 3: the (remembered) decision, with this cycle's probing and rationale faults."""
        inp, values, decision = self.decider.decide(graph, self._held)
        outcome = decision.outcome
        cfs = decision.counterfactuals
        if faults.cf_timeout:
            try:
                cfs = counterfactual_records(
                    probe(
                        inp,
                        values,
                        decision.factors,
                        TIMEOUT_BUDGET,
                        graph_edges(graph),
                        plans=self.decider.plans,
                    )
                )
            except BudgetExhaustedError:
                cfs = None
        if cfs is None:
            pending.append(
                ("counterfactual_timeout", {"budget": TIMEOUT_BUDGET, "factors": decision.factors})
            )
        rationale = decision.rationale
        if faults.truncate:
            phrases, tests, command = decision.phrases, outcome.tests, outcome.command
            capacity = rationale_size(phrases, tests, command, graph, factors=decision.factors) // 2
            buffer = RationaleBuffer(capacity)
            write_rationale(buffer, phrases, tests, command, graph, factors=decision.factors)
            rationale = buffer.rationale()
            kept = [f["node"] for f in rationale["factors"]]
            pending.append(
                (
                    "rationale_truncation",
                    {
                        "capacity": capacity,
                        "factors_kept": kept,
                        "factors_lost": [f for f in decision.factors if f not in kept],
                    },
                )
            )
        action = action_record(
            outcome,
            score=decision.score,
            alternatives=decision.alternatives,
            rationale=rationale,
            counterfactuals=cfs,
            intended=(0.0, 0.0),
        )
        return decision, action

    def _audit_faults(  # noqa: PLR0917 - private step of cycle(), called once
        self,
        seen: PerceptionOutput,
        graph: BeliefGraph,
        factors: list[str],
        logged_factors: list[str],
        faults: CycleFaults,
        pending: Pending,
    ) -> tuple[dict[str, str], Edge | None]:
        """Evidence-link corruption per entity, and the belief edge whose write fails."""
        entity_ids = {n.id for n in graph.nodes if n.kind == "entity"}
        corrupt: dict[str, str] = {}
        for eid in [e.id for e in seen.entities] + ["corridor"]:
            mode = self.injector.corrupt_entity()
            if mode is not None:
                corrupt[eid] = mode
                affected = [
                    f for f in logged_factors if eid in entities_under(f, graph.edges, entity_ids)
                ]
                pending.append(
                    (
                        "evidence_corruption",
                        {
                            "entity": eid,
                            "mode": mode,
                            "factors_affected": affected,
                        },
                    )
                )
        if not faults.edge_failure:
            return corrupt, None
        # Aim at an edge whose loss breaks some factor's chain to its entity.
        candidates = [(f, cut_edges(f, graph.edges, entity_ids)) for f in factors]
        candidates = [(f, cuts) for f, cuts in candidates if cuts]
        if not candidates:
            return corrupt, None
        factor, cuts = candidates[self.injector.pick(len(candidates))]
        edge = cuts[self.injector.pick(len(cuts))]
        kept = [e for e in graph.edges if e is not edge]
        broken = [f for f in logged_factors if not reaches_entity(f, kept, entity_ids)]
        pending.append(
            (
                "edge_write_failure",
                {
                    "edge": [edge.parent, edge.child],
                    "factor": factor,
                    "broken_factors": broken,
                },
            )
        )
        return corrupt, edge
