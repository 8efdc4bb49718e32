"""``RemoteLogger``, the Python client, against a real recorder: the same records give the
same log as ``AuditLogger`` in process; the control loop never waits for a recorder that is
not there; a record the recorder refuses comes back as a count, never as an exception."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from tests.outside import cli
from tests.trace_runtime.recorder.conftest import RecorderProcess, comparable_metrics
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.recorder import RemoteLogger
from trace_runtime.testing import synthetic_cycle

PERIOD_NS = 10_000_000


def _log(log: AuditLogger | RemoteLogger, cycles: int) -> None:
    for i in range(cycles):
        with log.cycle(i * PERIOD_NS) as c:
            c.sensor("/sensors/lidar", {"ranges": [1.0 + i / 100, 2.0], "cluster": i})
            p, b, a, e = synthetic_cycle(i)
            c.perception(p)
            c.belief(b)
            c.action(a)
            c.execution(e)


def test_remote_and_in_process_logs_of_the_same_cycles_are_the_same(
    recorder: RecorderProcess, tmp_path: Path
) -> None:
    with RemoteLogger(recorder.socket, robot_id="amr-1", period_s=0.01) as remote:
        _log(remote, 60)
        assert remote.flush()
        stats = remote.recorder_stats()["robot"]
        assert stats["written"] == 60 and stats["refused"] == 0
    assert remote.stats.sent == 60 and remote.stats.dropped == 0
    code, stderr = recorder.stop()
    assert code == 0, stderr

    local = tmp_path / "local"
    with AuditLogger(local, robot_id="amr-1", period_s=0.01, config=LoggerConfig()) as log:
        _log(log, 60)

    assert comparable_metrics(recorder.root) == comparable_metrics(local)
    remote_cycles = [c.payloads for c in open_log(recorder.root).iter_cycles()]
    local_cycles = [c.payloads for c in open_log(local).iter_cycles()]
    assert len(remote_cycles) == len(local_cycles) == 60
    assert remote_cycles == local_cycles


def test_a_refused_record_is_counted_and_the_next_seal_declares_it(
    recorder: RecorderProcess,
) -> None:
    with RemoteLogger(recorder.socket, robot_id="amr-1", period_s=0.01) as log:
        log.log_cycle(1_000, action={"command": "GO", "rationale": {"text": "ok"}})
        log.log_cycle(2_000, action={"command": "", "rationale": {"text": "no command"}})
        log.log_cycle(3_000, action={"command": "GO", "rationale": {"text": "ok"}})
        assert log.flush()
        assert log.stats.refused == 1 and "command" in log.stats.last_error
    recorder.stop()
    (robot,) = json.loads(cli("verify", recorder.root, "--json").stdout)["robots"]
    assert robot["cycles_valid"] == 2 and robot["declared_dropped"] == 1


def test_without_a_recorder_the_loop_runs_on_and_counts_its_drops(tmp_path: Path) -> None:
    started = time.monotonic()
    with RemoteLogger(
        tmp_path / "nobody.sock", robot_id="amr-1", period_s=0.01, connect_timeout_s=0.2
    ) as log:
        begun = time.monotonic()
        _log(log, 50)
        loop_s = time.monotonic() - begun
    assert loop_s < 0.5  # 50 cycles never waited for a connection
    assert time.monotonic() - started < 3
    assert log.stats.dropped_disconnected == 50 and log.stats.sent == 0


def test_a_recording_declared_in_the_hello_is_sealed_by_the_recorder(
    recorder: RecorderProcess, tmp_path: Path
) -> None:
    """A ROS 2 node feeding the recorder names its rosbag2 bag in the hello: the recorder
    declares it in the robot's log and seals every message of it, so an uncited message
    changed afterwards is found by verify (profile 1.4)."""
    from tests.rosbag_recorder import cdr
    from tests.trace_runtime.logger.test_recording_seals import RECORDER as ROSBAG
    from tests.trace_runtime.logger.test_recording_seals import rewrite

    bag = tmp_path / "node_bag"
    subprocess.run([sys.executable, str(ROSBAG), str(bag), "--messages", "40"], check=True)
    with RemoteLogger(recorder.socket, robot_id="node-1", period_s=0.05, recordings=(bag,)) as log:
        for i in range(80):
            p, b, a, e = synthetic_cycle(i)
            log.log_cycle(
                1_000_000_000 + i * 50_000_000, perception=p, belief=b, action=a, execution=e
            )
            time.sleep(0.03)  # the recorder's writer polls the bag every 0.5 s
        assert log.flush()
    code, _ = recorder.stop()
    assert code == 0
    done = cli("verify", recorder.root, "--json")
    assert done.returncode == 0, done.stdout
    assert "recording_unsealed" not in done.stdout and "recording_unchecked" not in done.stdout
    rewrite(next(bag.glob("*.mcap")), {12: cdr("odom forged")}, None)
    done = cli("verify", recorder.root, "--json")
    assert done.returncode == 1 and "1 changed: /odom" in done.stdout
