"""Profile 1.2's Merkle tree: its cost per cycle on the logger's writer, and verify's speed
before and after it (targets: <= 3 us a cycle; verify within 0.9x of before).

    .venv/bin/python bench/bench_tree.py [--cycles 3000] [--rounds 7]
    .venv/bin/python bench/bench_tree.py --verify-vs 84d9d2b --hours 0.5

Writer: the same logger code writes the same cycles (``synthetic_cycle`` records citing a
LiDAR reading, signed checkpoints every 10 s, one file, no fsync) with its tree and with the
tree switched off (``ChainWriter.tree = None``: no leaf hashes, checkpoints without tree or
note), in alternating rounds of one run; each ``ChainWriter.write_batch`` (the writer
thread's whole work per cycle: encoding, sealing, the tree, checkpoints, compression, the
write) is timed, and the medians per cycle are compared. The tree's own operations are
timed alone on the same seals too: ``leaf_hash`` + ``CompactRange.append`` per cycle, the
batch's ``state()`` snapshot, and a checkpoint's ``root()`` + note, amortised over 10 s.

Verify (``--verify-vs COMMIT``): ``bench/bench_verify.py --json`` in a worktree of COMMIT
(its logger writes its log, its verify reads it) and in this checkout (a 1.2 log), run in
child processes in turn, ``--repeat`` medians each; the ratio is after/before in cycles/s
(CPU). The worktree is removed afterwards.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.logger.chain_writer import ChainWriter
from trace_runtime.records import Evidence, Perception
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.merkle import CompactRange, leaf_hash
from trace_runtime.tlog.signed_note import NoteSigner, format_checkpoint, sign_note

PERIOD_NS = 100_000_000
TARGET_US = 3.0
CHECKOUT = Path(__file__).resolve().parents[1]


def _write(path: Path, cycles: int, signer: Ed25519Signer, *, tree: bool) -> list[int]:
    """Log ``cycles`` cycles; the ns each ``write_batch`` took (one cycle a batch)."""
    config = LoggerConfig(
        threaded=False, fsync_interval_s=None, checkpoint_interval_s=10.0, checkpoint_key=signer
    )
    variants = [synthetic_cycle(i) for i in range(50)]
    times: list[int] = []
    with AuditLogger(path, robot_id="amr-bench", config=config) as logger:
        chain: ChainWriter = logger._chain
        if not tree:
            chain.tree = None
        write = chain.write_batch

        def timed(batch: list) -> None:  # type: ignore[type-arg]
            started = time.perf_counter_ns()
            write(batch)
            times.append(time.perf_counter_ns() - started)

        chain.write_batch = timed  # type: ignore[method-assign]
        for i in range(cycles):
            perception, belief, action, execution = variants[i % len(variants)]
            with logger.cycle(i * PERIOD_NS) as c:
                ref = c.sensor("/sensors/lidar", {"ranges": [1.0 + (i % 97) / 50, 2.5], "i": i})
                entities = [
                    e.model_copy(
                        update={"evidence": [Evidence(sensor="lidar", weight=1.0, ref=ref)]}
                    )
                    for e in perception.entities
                ]
                c.perception(Perception(entities=entities, sensors_used=["lidar"]))
                c.belief(belief)
                c.action(action)
                c.execution(execution)
    return times


def _seals(path: Path) -> list[bytes]:
    from trace_runtime import open_log
    from trace_runtime.records import TOPIC_SEAL

    return [c.payloads[TOPIC_SEAL] for c in open_log(path).iter_cycles()]


def _isolated(seals: list[bytes], signer: Ed25519Signer, rounds: int) -> dict[str, float]:
    """The tree's own work on these seals, us per cycle (medians of ``rounds``)."""
    note_signer = NoteSigner("trace.local/amr-bench", signer, signer.public_key.raw)

    def per_cycle(work: object) -> float:
        runs = []
        for _ in range(rounds):
            started = time.perf_counter_ns()
            work()  # type: ignore[operator]
            runs.append((time.perf_counter_ns() - started) / len(seals) / 1000)
        return statistics.median(runs)

    def leaves() -> None:
        compact = CompactRange()
        grow = compact.append
        for s in seals:
            grow(leaf_hash(s))

    compact = CompactRange()
    for s in seals:
        compact.append(leaf_hash(s))

    def snapshots() -> None:
        for _ in seals:
            compact.state()

    def checkpoint() -> None:
        root = compact.root()
        [h.hex() for h in compact.hashes]
        sign_note(format_checkpoint(note_signer.name, compact.size, root), note_signer)

    started = time.perf_counter_ns()
    for _ in range(20):
        checkpoint()
    per_checkpoint_us = (time.perf_counter_ns() - started) / 20 / 1000
    out = {
        "leaf_and_append_us": per_cycle(leaves),
        "snapshot_us": per_cycle(snapshots),
        "checkpoint_tree_and_note_us": per_checkpoint_us,
        "checkpoint_per_cycle_us": per_checkpoint_us / 100,  # one per 10 s at 10 Hz
    }
    out["total_us"] = (
        out["leaf_and_append_us"] + out["snapshot_us"] + out["checkpoint_per_cycle_us"]
    )
    return out


def writer(cycles: int, rounds: int) -> dict[str, object]:
    signer = Ed25519Signer.generate()
    with_tree: list[float] = []
    without: list[float] = []
    with tempfile.TemporaryDirectory(prefix="bench-tree-") as tmp:
        for r in range(rounds):
            for tree in (True, False) if r % 2 == 0 else (False, True):
                path = Path(tmp) / f"r{r}-{tree}.mcap"
                times = _write(path, cycles, signer, tree=tree)
                (with_tree if tree else without).append(statistics.median(times) / 1000)
                if not tree:
                    path.unlink()
        seals = _seals(next(Path(tmp).glob("*True.mcap")))
        isolated = _isolated(seals, signer, rounds)
    a, b = statistics.median(with_tree), statistics.median(without)
    return {
        "cycles_per_round": cycles,
        "rounds": rounds,
        "write_batch_us_with_tree": round(a, 2),
        "write_batch_us_without_tree": round(b, 2),
        "tree_us_per_cycle_end_to_end": round(a - b, 2),
        "isolated": {k: round(v, 3) for k, v in isolated.items()},
        "target_us": TARGET_US,
    }


def _bench_verify(tree: Path, log: Path, hours: float, repeat: int) -> dict[str, float]:
    done = subprocess.run(
        [
            sys.executable,
            str(tree / "bench" / "bench_verify.py"),
            "--hours",
            str(hours),
            "--log",
            str(log),
            "--repeat",
            str(repeat),
            "--json",
        ],
        cwd=tree,
        env={"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        check=True,
    )
    result: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def verify_vs(commit: str, hours: float, repeat: int, turns: int) -> dict[str, object]:
    old = Path(tempfile.mkdtemp(prefix="old-verify-"))
    old.rmdir()
    subprocess.run(
        ["git", "worktree", "add", "--detach", str(old), commit], cwd=CHECKOUT, check=True
    )
    logs = Path(tempfile.mkdtemp(prefix="bench-tree-verify-"))
    try:
        before: list[float] = []
        after: list[float] = []
        anchored: dict[str, list[float]] = {"old": [], "new": []}
        for turn in range(turns):
            order = [(old, "old", before), (CHECKOUT, "new", after)]
            for tree, name, into in order if turn % 2 == 0 else reversed(order):
                result = _bench_verify(tree, logs / name, hours, repeat)
                into.append(result["verify_cpu_cycles_per_s"])
                anchored[name].append(result["verify_over_read_cpu"])
        b, a = statistics.median(before), statistics.median(after)
        return {
            "commit_before": commit,
            "hours": hours,
            "cycles": result["cycles"],
            "before_cycles_per_cpu_s": round(b),
            "after_cycles_per_cpu_s": round(a),
            "ratio_after_over_before": round(a / b, 3),
            "verify_over_read_cpu_before": statistics.median(anchored["old"]),
            "verify_over_read_cpu_after": statistics.median(anchored["new"]),
            "turns": turns,
        }
    finally:
        subprocess.run(
            ["git", "worktree", "remove", "--force", str(old)], cwd=CHECKOUT, check=False
        )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=3000, help="cycles per writer round")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--verify-vs", metavar="COMMIT", default=None)
    parser.add_argument("--hours", type=float, default=0.5, help="verify's log at 10 Hz")
    parser.add_argument("--repeat", type=int, default=3, help="verify runs per child")
    parser.add_argument("--turns", type=int, default=2, help="children per side, in turn")
    args = parser.parse_args()
    if args.verify_vs:
        print(json.dumps(verify_vs(args.verify_vs, args.hours, args.repeat, args.turns)))
    else:
        print(json.dumps(writer(args.cycles, args.rounds)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
