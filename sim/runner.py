"""Run the simulator: world -> sensors -> the four layers -> ``trace_runtime`` log.

``run(RunConfig(...))`` is the library entry point; the CLI only parses and renders. This
module owns the run (its options, outputs and result); one cycle of the robot is
``sim.pipeline``'s.
"""

from __future__ import annotations

import gc
import re
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

from sim.faults import (
    DEFAULT_ROBOT_ID,
    FailingOpener,
    FaultRates,
    TruthLog,
    truth_path_for,
)
from sim.nulllog import NullLogger
from sim.pipeline import Pipeline
from sim.scenarios import EPISODE_CYCLES, SCENARIOS
from sim.world import PERIOD_S
from trace_runtime import AuditLogger, LoggerConfig, TraceError
from trace_runtime.clock import EARLIEST_WALL_NS
from trace_runtime.errors import UsageError

PERIOD_NS = 100_000_000
CYCLES_PER_DAY = 864_000
SOFTWARE_VERSION = "trace-sim 0.1"
POLICY_VERSION = "fig2-v2"
"""v2: speed limit near people in the tree, hysteresis, counterfactuals as interventions."""
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
    start_ns: int | None = 0
    """The first cycle's time: ns on ``clock`` (``parse_start``). None: one period after the
    robot's last cycle in the log root ``out``, on that log's clock (``clock`` is then not
    used), as a real robot's clock goes on across a restart; 0 on ``clock`` for a robot
    new there."""
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
    checkpoint_key: str | Path | None = None
    """The robot's private key: a key file or a ``pkcs11:`` URI of a key in a token;
    checkpoints signed (``LoggerConfig.checkpoint_key``)."""
    next_key: str | Path | None = None
    """A key to rotate to (``LoggerConfig.next_key``): announced by ``checkpoint_key`` at the
    run's first checkpoint unless the robot's chain in the root already did; then it signs."""
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
    if config.start_ns is not None and config.start_ns < 0:
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
    if config.start_ns is None:
        config = replace(config, **_clock_going_on(out, config.robot_id))
    truth_path = truth_path_for(out, config.robot_id)
    opener = FailingOpener()
    truth, logger = _open_outputs(config, out, truth_path, opener)
    sim = Pipeline(config.seed, config.faults, logger, opener, truth)
    commands: dict[str, int] = {}
    per_scenario: dict[str, int] = {}
    started = time.perf_counter()
    done = 0
    start_ns = config.start_ns or 0
    try:
        with few_collections():
            for k, (scenario, new_episode) in enumerate(plan(config)):
                if new_episode:
                    sim.world.make_room(EPISODE_ROOM_M)
                    sim.world.actors = SCENARIOS[scenario].spawn(sim.world)
                command = sim.cycle(scenario, start_ns + k * PERIOD_NS)
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


def _clock_going_on(out: Path, robot_id: str) -> dict[str, Any]:
    """``start_ns`` and ``clock`` that go on one period after the robot's last cycle in the
    log root ``out`` (a restarted robot's clock does not go back to 0); 0 on a sim clock for a
    robot not there yet, or for a single file (never continued)."""
    if out.suffix == ".mcap" or not out.is_dir():
        return {"start_ns": 0, "clock": "sim"}
    from trace_runtime.logger.resume import resume_time

    last = resume_time(out, robot_id)
    if last is None:
        return {"start_ns": 0, "clock": "sim"}
    return {"start_ns": last[0] + PERIOD_NS, "clock": last[1]}


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
                    next_key=config.next_key,
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
