"""Recorder benchmarks (issue: recorder), each against its anchor measured in the same run.

    .venv/bin/python bench/bench_recorder.py [--quick]

1. the C++ client's cost on the control thread for a 4 KB cycle (``send_cycle``: copy into
   the ring), p50 and p99, against the budget (p50 <= 5 us, p99 <= 20 us); and the whole
   cost of the example robot (building the JSON and handing it over);
2. the Python ``RemoteLogger`` on the control thread against in-process ``AuditLogger``,
   the same built records, paced like a control loop (ratio of p50s);
3. throughput: cycles/s the recorder writes from one client sending as fast as the socket
   takes them, against the in-process logger fed the same plain dicts (ratio);
4. 20 C++ robots at 50 Hz into one recorder for ~10 s: cycles sent, dropped, written.

Medians and ratios, never one absolute time alone: this machine is shared and noisy.
Needs build/cpp_robot (scripts/build-cpp.sh).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import orjson

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.recorder import RemoteLogger
from trace_runtime.testing import synthetic_cycle

REPO = Path(__file__).resolve().parents[1]
CPP_ROBOT = REPO / "build" / "cpp_robot"
PERIOD_NS = 10_000_000


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


class _Recorder:
    """``trace-recorder serve`` as a process, as a robot's host runs it."""

    def __init__(self, where: Path) -> None:
        self.root, self.socket = where / "root", where / "rec.sock"
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        command = [sys.executable, "-m", "trace_runtime.recorder.cli", "serve"]
        command += ["--root", str(self.root), "--socket", str(self.socket)]
        self.proc = subprocess.Popen(command, stderr=subprocess.PIPE, text=True, env=env)
        assert self.proc.stderr is not None
        while "listening on" not in self.proc.stderr.readline():
            pass

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        self.proc.communicate(timeout=120)


def _cpp(socket_path: Path, robot_id: str, cycles: int, hz: float, beams: int) -> dict[str, float]:
    command = [str(CPP_ROBOT), "--socket", str(socket_path), "--robot-id", robot_id]
    command += ["--cycles", str(cycles), "--hz", str(hz), "--beams", str(beams), "--sim-time"]
    out = subprocess.run(command, capture_output=True, text=True, check=True).stdout
    numbers: dict[str, float] = {}
    for line in out.strip().splitlines()[-2:]:
        words = line.split()
        numbers |= {words[i]: float(words[i + 1]) for i in range(0, len(words), 2)}
    return numbers


# --- 1. the C++ client's control-thread cost -------------------------------------------


def cpp_client_cost(where: Path, cycles: int) -> dict[str, float]:
    recorder = _Recorder(where)
    try:
        return _cpp(recorder.socket, "bench-cpp", cycles, 100.0, beams=500)
    finally:
        recorder.stop()


# --- 2. RemoteLogger against AuditLogger on the control thread --------------------------


def _paced_costs(log: AuditLogger | RemoteLogger, cycles: int) -> list[float]:
    records = [synthetic_cycle(i) for i in range(cycles)]
    costs = []
    for i, (p, b, a, e) in enumerate(records):
        start = time.perf_counter_ns()
        with log.cycle(i * PERIOD_NS) as c:
            c.sensor("/sensors/lidar", {"ranges": [1.5, 1.6, 1.7], "cluster": i})
            c.perception(p)
            c.belief(b)
            c.action(a)
            c.execution(e)
        costs.append((time.perf_counter_ns() - start) / 1000)
        time.sleep(0.002)  # a control loop's pause: the writer threads run in between
    return costs


def python_clients(where: Path, cycles: int) -> dict[str, float]:
    recorder = _Recorder(where)
    try:
        with RemoteLogger(recorder.socket, robot_id="bench-remote", period_s=0.01) as remote:
            remote_costs = _paced_costs(remote, cycles)
    finally:
        recorder.stop()
    with AuditLogger(where / "local", robot_id="bench-local", period_s=0.01) as local:
        local_costs = _paced_costs(local, cycles)
    result = {
        "remote_p50_us": _percentile(remote_costs, 0.5),
        "remote_p99_us": _percentile(remote_costs, 0.99),
        "local_p50_us": _percentile(local_costs, 0.5),
        "local_p99_us": _percentile(local_costs, 0.99),
    }
    result["p50_ratio_remote_over_local"] = result["remote_p50_us"] / result["local_p50_us"]
    return result


# --- 3. throughput ------------------------------------------------------------------------


def _dict_cycles(n: int) -> list[dict[str, Any]]:
    out = []
    for i in range(n):
        layers = synthetic_cycle(i)
        names = ("perception", "belief", "action", "execution")
        pairs = zip(names, layers, strict=True)
        out.append({n: r.model_dump(mode="json", by_alias=True) for n, r in pairs})
    return out


def _frame(message: dict[str, Any]) -> bytes:
    body = orjson.dumps(message)
    return struct.pack(">I", len(body)) + body


def throughput(where: Path, cycles: int) -> dict[str, float]:
    dicts = _dict_cycles(cycles)
    # Two anchors, the better one counts: the in-process logger whose queue blocks when full
    # (the most its writer sustains without a loss) and with the default queue that drops
    # (the recorder's loggers keep it). All in cycles written per second, not handed over.
    anchors = {}
    for when_full in ("block", "drop"):
        config = LoggerConfig(when_full=when_full)
        start = time.perf_counter()
        with AuditLogger(where / when_full, robot_id="tp", period_s=0.01, config=config) as log:
            for i, layers in enumerate(dicts):
                log.log_cycle(i * PERIOD_NS, **layers)
        anchors[when_full] = (log.stats.written, log.stats.written / (time.perf_counter() - start))
    local_written, local = max(anchors.values(), key=lambda pair: pair[1])

    frames = [
        _frame({"kind": "cycle", "seq": i, "t_ns": i * PERIOD_NS, **layers})
        for i, layers in enumerate(dicts)
    ]
    recorder = _Recorder(where / "tp")
    try:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.connect(str(recorder.socket))
        hello = {"kind": "hello", "protocol": 1, "robot_id": "tp", "period_ns": PERIOD_NS}
        sock.sendall(_frame(hello))
        sock.recv(65536)  # welcome
        start = time.perf_counter()
        for frame in frames:
            sock.sendall(frame)
        sock.sendall(_frame({"kind": "bye"}))  # answered once the segment is finished
        sock.recv(65536)
        elapsed = time.perf_counter() - start
        sock.close()
    finally:
        recorder.stop()
    written = sum(1 for _ in open_log(where / "tp" / "root").iter_cycles())
    remote = written / elapsed
    return {
        "block_cycles_per_s": anchors["block"][1],
        "drop_cycles_per_s": anchors["drop"][1],
        "drop_written": anchors["drop"][0],
        "local_written": local_written,
        "local_cycles_per_s": local,
        "recorder_cycles_per_s": remote,
        "ratio_recorder_over_local": remote / local,
        "recorder_written": written,
    }


# --- 4. a fleet of C++ robots into one recorder ------------------------------------------


def fleet(where: Path, robots: int, seconds: float) -> dict[str, float]:
    hz = 50.0
    cycles = int(seconds * hz)
    recorder = _Recorder(where)
    try:
        command = [str(CPP_ROBOT), "--socket", str(recorder.socket), "--cycles", str(cycles)]
        command += ["--hz", str(hz), "--beams", "300"]
        procs = [
            subprocess.Popen([*command, "--robot-id", f"amr-{n:02d}"], stdout=subprocess.PIPE)
            for n in range(robots)
        ]
        outs = [p.communicate(timeout=seconds * 6 + 60)[0].decode() for p in procs]
    finally:
        recorder.stop()
    last = [dict(zip(o.split()[-8::2], map(float, o.split()[-7::2]), strict=True)) for o in outs]
    verified = subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", "verify", str(recorder.root), "--json"],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    report = json.loads(verified.stdout)
    return {
        "robots": robots,
        "cycles_each": cycles,
        "sent": sum(x["sent"] for x in last),
        "dropped": sum(x["dropped"] for x in last),
        "written": report["cycles_valid"],
        "verify_ok": report["ok"],
        "worst_p99_us": max(x["p99_us"] for x in last),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer cycles, 3 s fleet")
    args = parser.parse_args()
    if not CPP_ROBOT.exists():
        subprocess.run(["bash", str(REPO / "scripts" / "build-cpp.sh")], check=True)
    n = 300 if args.quick else 1000
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(tmp)
        cpp = cpp_client_cost(where / "cpp", n)
        print(
            f"1. C++ client, {cpp['cycle_bytes']:.0f} B cycle: send_cycle p50 "
            f"{cpp['send_p50_us']:.2f} us (budget 5), p99 {cpp['send_p99_us']:.2f} us "
            f"(budget 20), max {cpp['send_max_us']:.1f} us; whole robot (build JSON + send) "
            f"p50 {cpp['p50_us']:.1f} us p99 {cpp['p99_us']:.1f} us; sent {cpp['sent']:.0f} "
            f"dropped {cpp['dropped']:.0f}"
        )
        py = python_clients(where / "py", n)
        print(
            f"2. control thread, Python: RemoteLogger p50 {py['remote_p50_us']:.1f} us "
            f"p99 {py['remote_p99_us']:.1f} us; AuditLogger p50 {py['local_p50_us']:.1f} us "
            f"p99 {py['local_p99_us']:.1f} us; ratio {py['p50_ratio_remote_over_local']:.2f}x"
        )
        n_tp = 2000 if args.quick else 10000
        tp = throughput(where / "tp", n_tp)
        print(
            f"3. throughput: recorder {tp['recorder_cycles_per_s']:.0f} cycles/s "
            f"({tp['recorder_written']} of {n_tp} written); in-process logger, queue "
            f"blocking {tp['block_cycles_per_s']:.0f} cycles/s, queue dropping "
            f"{tp['drop_cycles_per_s']:.0f} cycles/s ({tp['drop_written']} written); ratio to "
            f"the better {tp['ratio_recorder_over_local']:.2f}x (target >= 1.0)"
        )
        fl = fleet(where / "fleet", 20, 3.0 if args.quick else 10.0)
        print(
            f"4. {fl['robots']} C++ robots x {fl['cycles_each']} cycles at 50 Hz: sent "
            f"{fl['sent']:.0f}, dropped {fl['dropped']:.0f}, written {fl['written']}, "
            f"verify ok {fl['verify_ok']}, worst robot p99 {fl['worst_p99_us']:.0f} us"
        )


if __name__ == "__main__":
    main()
