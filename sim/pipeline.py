"""The simulated robot, one decision cycle at a time: world -> sensors -> the four layers ->
the logger, with this cycle's injected faults, and the ground truth of each cycle written
once its write is known to have kept or lost it (``Pipeline``). ``sim.runner`` drives it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from sim.belief import BeliefGraph, Edge, build_belief
from sim.counterfactual import BudgetExhaustedError, probe
from sim.decision import Decider, Decision, graph_edges
from sim.execution import Actuator, Executed, Steering
from sim.faults import CycleFaults, FailingOpener, FaultInjector, FaultRates, TruthLog
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
from sim.sensors import (
    CameraDetection,
    LidarScan,
    detect_camera,
    range_ultrasonic,
    scan_lidar,
)
from sim.world import World
from trace_runtime import AuditLogger
from trace_runtime.flags import SCENARIO_FLAG

__all__ = ["TIMEOUT_BUDGET", "Pipeline"]

TIMEOUT_BUDGET = 2
"""Probe budget (policy evaluations) left when a counterfactual timeout is injected."""

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


class _Readings(NamedTuple):
    """One cycle's sensor readings and the corridor ahead, before perception."""

    pose: tuple[float, float, float]
    scan: LidarScan
    detections: list[CameraDetection] | None
    us_range: float | None
    corridor_length: float


@dataclass(slots=True)
class _Unsettled:
    """A committed cycle whose write outcome (and so whose ground truth) is not known yet."""

    cycle: int
    t_ns: int
    scenario: str
    write_timeout: bool
    pending: Pending


class Pipeline:
    """The robot: world, sensors, the four layers and the logger, one cycle at a time."""

    def __init__(
        self,
        seed: int,
        faults: FaultRates,
        logger: AuditLogger | NullLogger,
        opener: FailingOpener,
        truth: TruthLog,
    ) -> None:
        seeds = np.random.SeedSequence(seed).spawn(4)
        self.world = World(np.random.default_rng(seeds[0]))
        self.sensor_rng = np.random.default_rng(seeds[1])
        self.injector = FaultInjector(faults, np.random.default_rng(seeds[2]))
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
        read = self._read_sensors(faults, pending)
        # The injected timeout fails whatever write this cycle's commit makes: the cycle's own
        # (one cycle per write), or with batching the batch it completes; else nothing.
        opener.set_failing(faults.write_timeout)
        try:
            with logger.cycle(t_ns) as c:
                cycle_no = c.cycle
                # Layer 1: sensors -> entities; the readings used are logged as they are read.
                seen = self.perceiver.step(
                    cycle=cycle_no,
                    pose=read.pose,
                    speed=actuator.linear,
                    scan=None if faults.lidar_down else read.scan,
                    detections=read.detections,
                    us_range=read.us_range,
                    corridor_length=read.corridor_length,
                    log_sensor=c.sensor,
                )
                # Layer 2
                graph = build_belief(seen, read.pose, actuator.linear)
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
                c.perception(perception_record(seen, read.pose, corrupt))
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

    def _read_sensors(self, faults: CycleFaults, pending: Pending) -> _Readings:
        """This cycle's readings, drawn in the order the goldens pin (lidar, then the camera
        unless it is down, then the ultrasonic), and each sensor that is down noted."""
        world = self.world
        pose = world.robot_pose()
        scan = scan_lidar(world, self.sensor_rng)
        detections = (
            None if faults.camera_down else detect_camera(world, scan.truth, self.sensor_rng)
        )
        us_range = range_ultrasonic(scan.truth, self.sensor_rng)
        for sensor, down in (("lidar", faults.lidar_down), ("camera", faults.camera_down)):
            if down:
                pending.append(("sensor_unavailable", {"sensor": sensor}))
        corridor_length = min(
            CORRIDOR_MAX_M, world.route.to_end(world.robot.s, world.robot.direction) + 1.0
        )
        return _Readings(pose, scan, detections, us_range, corridor_length)

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
