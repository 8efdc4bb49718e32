"""Benchmark: simulated + logged cycles per second in routine operation (``--duration`` mode).

Budget: >= 5,000 cycles/s simulated and logged (a 24 h run, 864,000 cycles, in < 3 min).

Measured in one invocation, each figure the median of ``--runs`` (default 3):

1. end to end: ``sim.run`` of ``--cycles`` (>= 20,000) cycles the way ``trace-sim run
   --duration`` makes them (faults at the paper's rates, ``--batch`` 50 cycles per write).
   Wall-clock and process-CPU cycles/s: this machine is shared, so wall time also counts
   other people's work; CPU time is the steadier figure.
2. the simulator alone, measured: the same runs with the logger replaced by a stand-in that
   takes every record and keeps nothing (so no write ever fails: the injected audit-write
   timeouts lose nothing, which changes nothing the simulator computes but which evidence
   perception forgets). Interleaved with the runs of 1, so both see the same machine.
3. anchor, the logger alone: the very records the simulator handed to ``AuditLogger`` in a
   tapped run, replayed through a fresh ``AuditLogger`` with the same configuration
   (synchronous, same batch, same garbage-collector settings as ``sim.run``).
4. the simulator alone, derived: 1 / (1/total - 1/logger), on CPU time (a cross-check of 2).
   With ``--vs TREE`` (another checkout, e.g. the tree before a change), the simulator +
   logger and the simulator alone of this tree and of TREE, each in a fresh child process,
   in turn, ``--runs`` rounds: the medians and the median of the pairwise ratios.
5. where the time goes, CPU microseconds per cycle: the simulator's stages, from a run with
   thin timing wrappers; the logger's parts, each timed on its own on the captured records
   (check_layer as the builder calls it, the writer's encoding, sensor refs, seals, chunk
   writing); the rest of the logger is its bookkeeping (the replay total minus those parts).

Run: ``.venv/bin/python bench/bench_sim.py [--cycles 20000] [--runs 3] [--batch 50] [--vs TREE
[--vs-only]]``
"""

from __future__ import annotations

import argparse
import io
import logging
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sim import FaultRates, RunConfig, run, runner
from sim.execution import Actuator
from sim.perception import Perceiver
from sim.runner import few_collections
from trace_runtime import AuditLogger, CycleBuilder, LoggerConfig, LoggerStats, SessionInfo
from trace_runtime.chain import digest
from trace_runtime.encoding.codec import (
    check_layer,
    encode_checked,
    encode_json,
    encode_seal_fields,
)
from trace_runtime.logger.mcap_out import OutMessage
from trace_runtime.logger.segment_writer import SegmentWriter
from trace_runtime.records import GENESIS, LAYER_MODELS, EvidenceRef

BUDGET = 5_000
DAY = 864_000
PERIOD_NS = 100_000_000
LAYERS = tuple(LAYER_MODELS)
_ADD = dict(zip(LAYERS, ("perception", "belief", "action", "execution"), strict=True))


@dataclass
class Captured:
    """One cycle as the simulator handed it to the logger."""

    t_ns: int
    sensors: list[tuple[str, Any]]
    layers: list[tuple[str, Any]]


class _Tap:
    """Stands in for a ``CycleBuilder``: records each call, then makes it."""

    def __init__(self, inner: CycleBuilder, into: list[Captured]) -> None:
        self._inner = inner
        self.cycle = inner.cycle
        self._cap = Captured(inner.t_ns, [], [])
        into.append(self._cap)

    def sensor(self, topic: str, payload: Any) -> EvidenceRef:
        self._cap.sensors.append((topic, payload))
        return self._inner.sensor(topic, payload)

    def _layer(self, topic: str, record: Any, add: Callable[[Any], None]) -> None:
        self._cap.layers.append((topic, record))
        add(record)

    def perception(self, record: Any) -> None:
        self._layer(LAYERS[0], record, self._inner.perception)

    def belief(self, record: Any) -> None:
        self._layer(LAYERS[1], record, self._inner.belief)

    def action(self, record: Any) -> None:
        self._layer(LAYERS[2], record, self._inner.action)

    def execution(self, record: Any) -> None:
        self._layer(LAYERS[3], record, self._inner.execution)

    def __enter__(self) -> _Tap:
        self._inner.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._inner.__exit__(*exc)


def _capture(config: RunConfig) -> list[Captured]:
    """Run the simulator and keep every record it hands to the logger."""
    captured: list[Captured] = []

    class TappedLogger(AuditLogger):
        def cycle(self, t_ns: int | None = None) -> Any:
            return _Tap(super().cycle(t_ns), captured)

    names = vars(runner)  # the logger class the runner looks up when it starts a run
    names["AuditLogger"] = TappedLogger
    try:
        run(config)
    finally:
        names["AuditLogger"] = AuditLogger
    return captured


class _NullRef:
    """What a record needs of an evidence ref (its topic and time), and nothing else."""

    __slots__ = ("log_time_ns", "topic")

    def __init__(self, topic: str, log_time_ns: int) -> None:
        self.topic, self.log_time_ns = topic, log_time_ns


class _NullCycle:
    """A ``CycleBuilder`` stand-in that takes the records and keeps nothing."""

    def __init__(self, logger: _NullLogger, cycle: int, t_ns: int) -> None:
        self._logger, self.cycle, self.t_ns = logger, cycle, t_ns

    def sensor(self, topic: str, payload: Any) -> _NullRef:
        return _NullRef(topic, self.t_ns)

    def perception(self, record: Any) -> None:
        pass

    def belief(self, record: Any) -> None:
        pass

    def action(self, record: Any) -> None:
        pass

    def execution(self, record: Any) -> None:
        pass

    def __enter__(self) -> _NullCycle:
        return self

    def __exit__(self, *exc: object) -> None:
        self._logger.committed()


class _NullLogger:
    """An ``AuditLogger`` stand-in: cycles are counted as written a batch at a time."""

    def __init__(self, out: Path, *, config: LoggerConfig, **_: Any) -> None:
        self.stats = LoggerStats()
        self._batch = config.batch_cycles
        self._next = self._pending = 0

    def cycle(self, t_ns: int) -> _NullCycle:
        self._next += 1
        return _NullCycle(self, self._next - 1, t_ns)

    def committed(self) -> None:
        self.stats.committed += 1
        self._pending += 1
        if self._pending >= self._batch:
            self.close()

    def close(self) -> None:
        self.stats.written += self._pending
        self._pending = 0


def _sim_only(config: RunConfig) -> float:
    """CPU seconds of ``sim.run(config)`` with the logger replaced by ``_NullLogger``."""
    names = vars(runner)
    names["AuditLogger"] = _NullLogger
    try:
        start = time.process_time()
        run(config)
        return time.process_time() - start
    finally:
        names["AuditLogger"] = AuditLogger


def _run_cpu(config: RunConfig) -> float:
    """CPU seconds of ``sim.run(config)``, simulator and logger."""
    start = time.process_time()
    run(config)
    return time.process_time() - start


def _child(tree: Path, what: str, args: argparse.Namespace) -> float:
    """CPU seconds of one measurement (``what``: ``sim`` alone, or ``full``, simulator and
    logger) on ``--cycles`` cycles, in a fresh process importing ``sim`` (and
    ``trace_runtime``) from ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    argv = [sys.executable, __file__, "--child", what, "--cycles", str(args.cycles)]
    argv += ["--seed", str(args.seed), "--faults", args.faults, "--batch", str(args.batch)]
    done = subprocess.run(argv, env=env, cwd=tree, capture_output=True, text=True, check=True)
    return float(done.stdout.split()[-1])


def _compare_trees(vs: Path, args: argparse.Namespace) -> None:
    """Print the simulator + logger, and the simulator alone, of this tree against ``vs``:
    ``--runs`` rounds of child processes in turn (this tree, then ``vs``; full, then sim
    alone), the medians and the median of the pairwise ratios."""
    here = Path(__file__).resolve().parents[1]
    n = args.cycles
    times: dict[tuple[str, str], list[float]] = defaultdict(list)
    for _ in range(args.runs):
        for what in ("full", "sim"):
            times["ours", what].append(_child(here, what, args))
            times["theirs", what].append(_child(vs, what, args))
    print(
        f"this tree vs {vs} ({args.runs} rounds of child processes in turn, "
        f"{n:,} cycles each, CPU time, medians)"
    )
    for what, label in (("full", "sim + logger"), ("sim", "sim alone")):
        ours, theirs = times["ours", what], times["theirs", what]
        ratios = sorted(t / o for o, t in zip(ours, theirs, strict=True))
        print(
            f"  {label:13s} this tree {n / statistics.median(ours):7,.0f} cycles/s "
            f"({1e6 * statistics.median(ours) / n:4.0f} us)   {vs.name} "
            f"{n / statistics.median(theirs):7,.0f} cycles/s "
            f"({1e6 * statistics.median(theirs) / n:4.0f} us)   speed-up "
            f"{statistics.median(ratios):.2f}x (pairs {', '.join(f'{r:.2f}' for r in ratios)})"
        )
    print()


def _replay(cycles: list[Captured], out: Path, batch: int) -> float:
    """CPU seconds for ``AuditLogger`` to take and write ``cycles``."""
    logger = AuditLogger(
        out,
        robot_id="bench",
        clock="sim",
        config=LoggerConfig(threaded=False, fsync_interval_s=None, batch_cycles=batch),
    )
    with few_collections():
        start = time.process_time()
        for cap in cycles:
            with logger.cycle(cap.t_ns) as c:
                for topic, payload in cap.sensors:
                    c.sensor(topic, payload)
                for topic, record in cap.layers:
                    getattr(c, _ADD[topic])(record)
        logger.close()
        return time.process_time() - start


def _cpu(fn: Callable[[], object], runs: int) -> float:
    """Median CPU seconds of ``fn()``."""
    times = []
    for _ in range(runs):
        with few_collections():
            start = time.process_time()
            fn()
            times.append(time.process_time() - start)
    return statistics.median(times)


def _logger_parts(cycles: list[Captured], batch: int, runs: int) -> dict[str, float]:
    """CPU seconds of each part of the logger's work on ``cycles``, each timed on its own."""
    # What CycleBuilder does with a layer record (check_layer: a plain dict is validated by
    # the msgspec mirror, or by pydantic when it holds a model, and encoded at once; a built
    # record is kept), then what the writer does with the value (encode_checked).
    checked = [
        [(topic, check_layer(LAYER_MODELS[topic], k, cap.t_ns, rec)) for topic, rec in cap.layers]
        for k, cap in enumerate(cycles)
    ]
    encoded = [
        [(topic, encode_checked(k, cap.t_ns, LAYER_MODELS[topic], v)) for topic, v in layers]
        for k, (cap, layers) in enumerate(zip(cycles, checked, strict=True))
    ]
    sensor_data = [[(t, encode_json(p)) for t, p in cap.sensors] for cap in cycles]

    def validate() -> None:
        for k, cap in enumerate(cycles):
            for topic, rec in cap.layers:
                check_layer(LAYER_MODELS[topic], k, cap.t_ns, rec)

    def encode() -> None:
        for k, (cap, layers) in enumerate(zip(cycles, checked, strict=True)):
            for topic, v in layers:
                encode_checked(k, cap.t_ns, LAYER_MODELS[topic], v)

    def sensor_refs() -> None:  # what CycleBuilder.sensor does per reading
        for cap in cycles:
            for seq, (topic, payload) in enumerate(cap.sensors):
                data = encode_json(payload)
                EvidenceRef(topic=topic, log_time_ns=cap.t_ns, sequence=seq, digest=digest(data))

    def seals() -> None:
        prev = GENESIS
        for k, (cap, layers) in enumerate(zip(cycles, encoded, strict=True)):
            digests = {topic: digest(data) for topic, data in layers}
            prev = digest(encode_seal_fields(k, cap.t_ns, digests, prev, 0))

    def chunks() -> None:
        writer = SegmentWriter(io.BytesIO(), SessionInfo(robot_id="bench", period_ns=PERIOD_NS))
        ids = {topic: writer.channel(topic) for topic in ("/trace/seal", *LAYERS)}
        for topic in {tp for rows in sensor_data for tp, _ in rows}:
            ids[topic] = writer.channel(topic)
        fake_seal = b"x" * 400  # a seal's size; its content does not change the cost
        for first in range(0, len(cycles), batch):
            messages = []
            for k in range(first, min(first + batch, len(cycles))):
                t = cycles[k].t_ns
                messages += [OutMessage(ids[tp], k, t, d) for tp, d in sensor_data[k]]
                messages += [OutMessage(ids[tp], k, t, d) for tp, d in encoded[k]]
                messages.append(OutMessage(ids["/trace/seal"], k, t, fake_seal))
            writer.write_batch(messages)

    return {
        "layer records: check_layer (validate, encode dicts)": _cpu(validate, runs),
        "writer: encode_checked (encodes built records)": _cpu(encode, runs),
        "sensor refs (encode, sha256, EvidenceRef)": _cpu(sensor_refs, runs),
        "seals (digests, seal bytes)": _cpu(seals, runs),
        "chunk writing (pack, zstd, write)": _cpu(chunks, runs),
    }


_STAGES: tuple[tuple[Any, str, str], ...] = (
    (runner, "scan_lidar", "LiDAR ray casting"),
    (runner, "detect_camera", "camera detector"),
    (runner, "range_ultrasonic", "ultrasonic"),
    (Perceiver, "step", "perception (clustering, tracking, fusion)"),
    (runner, "build_belief", "belief graph"),
    (runner._Pipeline, "_decide", "decision (policy, alternatives, probes, rationale)"),
    (Actuator, "step", "execution (actuator, compliance)"),
    (runner, "perception_record", "records: perception"),
    (runner, "belief_record", "records: belief"),
    (runner, "execution_record", "records: execution"),
    (runner._Pipeline, "_audit_faults", "audit-trail fault injection"),
    (CycleBuilder, "sensor", "logger: sensor()"),
    (CycleBuilder, "_add", "logger: layer records (check_layer)"),
    (CycleBuilder, "commit", "logger: commit (encode, seal, write)"),
)


def _sim_stages(config: RunConfig) -> tuple[dict[str, float], float]:
    """CPU seconds per stage in one run with timing wrappers, and the run's CPU total."""
    spent: defaultdict[str, float] = defaultdict(float)
    originals = []
    for owner, name, label in _STAGES:
        fn = getattr(owner, name)
        originals.append((owner, name, fn))

        def timed(*args: Any, _fn: Any = fn, _label: str = label, **kwargs: Any) -> Any:
            start = time.thread_time()
            try:
                return _fn(*args, **kwargs)
            finally:
                spent[_label] += time.thread_time() - start

        setattr(owner, name, timed)
    try:
        start = time.process_time()
        run(config)
        total = time.process_time() - start
    finally:
        for owner, name, fn in originals:
            setattr(owner, name, fn)
    # perception calls sensor() itself: count that time once, as the logger's.
    spent["perception (clustering, tracking, fusion)"] -= spent["logger: sensor()"]
    return dict(spent), total


def main() -> None:
    # Injected audit-write timeouts make the logger warn; the run's counts say the same.
    logging.getLogger("trace_runtime").setLevel(logging.ERROR)
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cycles", type=int, default=20_000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--batch", type=int, default=runner.DURATION_BATCH)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--faults", choices=("on", "off"), default="on")
    parser.add_argument("--replay-cycles", type=int, default=5_000)
    parser.add_argument("--vs", type=Path, help="another checkout to compare the simulator with")
    parser.add_argument(
        "--vs-only", action="store_true", help="with --vs: only the comparison of the two trees"
    )
    parser.add_argument("--child", choices=("sim", "full"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    faults = FaultRates() if args.faults == "on" else FaultRates.off()
    n, batch = args.cycles, args.batch
    if args.child is not None:  # one measurement for --vs, in this process
        with tempfile.TemporaryDirectory() as tmp:
            config = RunConfig(
                out=Path(tmp) / "sim.mcap",
                total_cycles=n,
                seed=args.seed,
                faults=faults,
                batch_cycles=batch,
            )
            print(_sim_only(config) if args.child == "sim" else _run_cpu(config))
        return
    if args.vs is not None:
        _compare_trees(args.vs.resolve(), args)
        if args.vs_only:
            return

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)

        def config(name: str, cycles: int) -> RunConfig:
            return RunConfig(
                out=root / name,
                total_cycles=cycles,
                seed=args.seed,
                faults=faults,
                batch_cycles=batch,
            )

        walls, cpus, sims = [], [], []
        result = None
        for k in range(args.runs):
            start = time.process_time()
            result = run(config(f"run{k}.mcap", n))
            cpus.append(time.process_time() - start)
            walls.append(result.elapsed_s)
            sims.append(_sim_only(config(f"sim{k}.mcap", n)))
        assert result is not None
        captured = _capture(config("tap.mcap", args.replay_cycles))
        replays = [_replay(captured, root / f"replay{k}.mcap", batch) for k in range(args.runs)]
        parts = _logger_parts(captured, batch, args.runs)
        stages, staged_total = _sim_stages(config("stages.mcap", args.replay_cycles))

    total_wall = n / statistics.median(walls)
    total_cpu = n / statistics.median(cpus)
    logger_cpu = len(captured) / statistics.median(replays)
    sim_derived = 1.0 / max(1e-12, 1.0 / total_cpu - 1.0 / logger_cpu)
    sim_cpu = n / statistics.median(sims)
    per_cycle = result.bytes_written / max(1, result.written)

    def us(seconds: float, cycles: int) -> str:
        return f"{1e6 * seconds / cycles:7.1f} us"

    print(
        f"sim + logging, {n:,} cycles, --batch {batch}, faults {args.faults}, "
        f"median of {args.runs} (dropped {result.dropped} of {result.cycles:,} in the last)"
    )
    print(
        f"  wall clock       {total_wall:8,.0f} cycles/s   "
        f"({total_wall / BUDGET:.2f}x the {BUDGET:,} budget; 24 h in "
        f"{DAY / total_wall / 60:.1f} min)"
    )
    print(
        f"  process CPU      {total_cpu:8,.0f} cycles/s   "
        f"({total_cpu / BUDGET:.2f}x the budget; 24 h in {DAY / total_cpu / 60:.1f} min)"
    )
    print(
        f"anchor: logger alone on the sim's records ({len(captured):,} cycles replayed, "
        "same config)"
    )
    print(
        f"  process CPU      {logger_cpu:8,.0f} cycles/s   "
        f"({1e6 / logger_cpu:.0f} us a cycle; {logger_cpu / BUDGET:.2f}x the budget)"
    )
    print("sim alone (logger replaced by a stand-in that keeps nothing, same runs)")
    print(
        f"  process CPU      {sim_cpu:8,.0f} cycles/s   ({1e6 / sim_cpu:.0f} us a cycle; "
        f"derived from the two above: {1e6 / sim_derived:.0f} us)"
    )
    print(
        f"split of a cycle: sim {1e6 / sim_cpu:.0f} us + logger {1e6 / logger_cpu:.0f} us "
        f"(alone) = {1e6 / sim_cpu + 1e6 / logger_cpu:.0f} us; measured together "
        f"{1e6 / total_cpu:.0f} us; the budget allows {1e6 / BUDGET:.0f} us"
    )
    print(f"bytes per cycle    {per_cycle:,.0f} B (MCAP, zstd chunks of {batch} cycles)")
    print()
    print(
        f"where a cycle's CPU time goes ({args.replay_cycles:,} cycles; "
        f"{us(staged_total, args.replay_cycles)} with the timing wrappers' own cost):"
    )
    for label, seconds in sorted(stages.items(), key=lambda kv: -kv[1]):
        print(f"  {label:52s} {us(seconds, args.replay_cycles)}")
    rest = staged_total - sum(stages.values())
    print(
        f"  {'rest of the loop (world, faults, flags, wrappers)':52s} "
        f"{us(rest, args.replay_cycles)}"
    )
    print(f"the logger's parts, each on its own ({len(captured):,} cycles):")
    for label, seconds in parts.items():
        print(f"  {label:52s} {us(seconds, len(captured))}")
    bookkeeping = statistics.median(replays) - sum(parts.values())
    print(f"  {'bookkeeping (builders, hand-over, messages)':52s} {us(bookkeeping, len(captured))}")
    print(f"  {'= logger alone':52s} {us(statistics.median(replays), len(captured))}")
    print()
    for name, rate in (("process CPU", total_cpu), ("wall clock", total_wall)):
        verdict = "PASS" if rate >= BUDGET else f"FAIL ({rate:,.0f} < {BUDGET:,} cycles/s)"
        print(f"verdict, {name:12s} {verdict}")


if __name__ == "__main__":
    main()
