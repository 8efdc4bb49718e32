"""Benchmark: what sealing a robot's rosbag2 recording costs (profile 1.4), against what its
bytes cost to read.

A recording of ``--messages`` messages of ``--size`` bytes on two topics is written by
``rosbags`` in another process (``tests/rosbag_recorder.py``), split in ``--splits`` files.
Measured in the same run, medians over ``--repeat`` runs:

- ``follow``: ``RecordingSeals`` reading the whole recording and sealing every window (what
  the writer thread does over a robot's run, here all at once);
- ``floor`` (anchor): the plain ``mcap`` reader iterating every message and SHA-256 of each
  message's data, the least any seal of every message must do;
- ``verify``: ``RecordingCheck`` checking every sealed window against the recording;
- ``logger``: the time an ``AuditLogger`` (``threaded=False``, so the writer's work is done
  in ``log_cycle``) spends writing ``--cycles`` cycles while sealing the whole recording,
  against the same cycles without a recording (anchor): what the robot's writer pays.

    .venv/bin/python bench/bench_recordings.py --messages 4000 --size 20000 --repeat 3
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from mcap.reader import make_reader

from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.gaps import CycleRange
from trace_runtime.logger.recording_seals import RecordingBatch, RecordingFollower
from trace_runtime.reading.recordings import Recordings, recording_files
from trace_runtime.testing import synthetic_cycle
from trace_runtime.verification.recording_check import RecordingCheck
from trace_runtime.verification.sink import FindingSink, SegmentReporter

RECORDER = Path(__file__).resolve().parents[1] / "tests" / "rosbag_recorder.py"


def median_s(run: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        run()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def floor(bag: Path) -> int:
    count = 0
    for path in recording_files(bag):
        with path.open("rb") as stream:
            for _schema, _channel, message in make_reader(stream).iter_messages():
                hashlib.sha256(message.data).digest()
                count += 1
    return count


def follow(bag: Path) -> list[dict[str, object]]:
    follower = RecordingFollower(bag.name, bag, window_ns=1_000_000_000, settle_ns=0)
    windows: list[dict[str, object]] = []
    while True:
        out = RecordingBatch()
        follower.poll(out, time.monotonic() + 3600)  # as if idle: the last window is sealed too
        windows += out.windows
        if not out.windows:
            return windows


def verify(bag: Path, windows: list[dict[str, object]]) -> None:
    check = RecordingCheck(Recordings.open([bag]))
    report = SegmentReporter(FindingSink(), "bench", "bench", 0)
    where = CycleRange(0, 0, 0, 0)
    payload = json.dumps({"cycle": 0, "t_ns": 0, "windows": windows}).encode()
    check.sealed(payload, where, report)
    check.finish()
    assert not report.sink.findings, report.sink.findings


def logger(root: Path, bag: Path | None, cycles: int) -> float:
    """Seconds spent in ``log_cycle`` (with ``threaded=False`` the writer's work, the
    recording's sealing included, is done there), the pauses for the poll left out."""
    config = LoggerConfig(
        threaded=False,
        fsync_interval_s=None,
        recordings=(bag,) if bag else (),
        recording_settle_s=0.0,
    )
    variants = [synthetic_cycle(i) for i in range(20)]
    spent = 0.0
    with AuditLogger(root, robot_id="bench", period_s=0.05, config=config) as log:
        for i in range(cycles):
            p, b, a, e = variants[i % len(variants)]
            started = time.perf_counter()
            log.log_cycle(
                1_000_000_000 + i * 50_000_000, perception=p, belief=b, action=a, execution=e
            )
            spent += time.perf_counter() - started
            if i % 50 == 0:
                time.sleep(0.5)  # let the writer's 0.5 s poll come round
    return spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=4000)
    parser.add_argument("--size", type=int, default=20_000)
    parser.add_argument("--splits", type=int, default=4)
    parser.add_argument("--cycles", type=int, default=400)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bench_bag"
        subprocess.run(
            [
                sys.executable,
                str(RECORDER),
                str(bag),
                "--messages",
                str(args.messages),
                "--size",
                str(args.size),
                "--splits",
                str(args.splits),
            ],
            check=True,
            capture_output=True,
        )
        size_mb = sum(p.stat().st_size for p in recording_files(bag)) / 1e6
        windows = follow(bag)
        results = {
            "recording_mb": round(size_mb, 1),
            "messages": floor(bag),
            "windows": len(windows),
            "floor_s": median_s(lambda: floor(bag), args.repeat),
            "follow_s": median_s(lambda: follow(bag), args.repeat),
            "verify_s": median_s(lambda: verify(bag, windows), args.repeat),
        }
        results["logger_plain_s"] = statistics.median(
            logger(Path(tmp) / f"plain{n}", None, args.cycles) for n in range(args.repeat)
        )
        results["logger_sealing_s"] = statistics.median(
            logger(Path(tmp) / f"seal{n}", bag, args.cycles) for n in range(args.repeat)
        )
    results["follow_over_floor"] = round(results["follow_s"] / results["floor_s"], 2)
    results["verify_over_floor"] = round(results["verify_s"] / results["floor_s"], 2)
    results["logger_ratio"] = round(results["logger_sealing_s"] / results["logger_plain_s"], 2)
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
