"""End to end with nothing but real parts: the logger submits its checkpoints to a real
``witness serve`` process while it logs (``LoggerConfig(witness=URL)``; unthreaded, so its
segments rotate by log time: 5 s segments of 200 cycles at 10 Hz), someone deletes the
newest segment, and ``verify --witness`` finds it; a robot whose witness was down keeps
logging, counts the failures, and ``witness push`` catches the witness up afterwards."""

from __future__ import annotations

import shutil
import socket
from collections.abc import Callable
from pathlib import Path

from tests.trace_audit.conftest import fill_cycle
from tests.trace_audit.witness.conftest import Keys, WitnessProcess, run_cli
from tests.trace_audit.witness.test_tail import PERIOD_NS, T0_NS, verify
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.tlog.cosignature_store import read_cosigned
from trace_runtime.tlog.keys import load_signer


def _log(root: Path, keys: Keys, url: str, cycles: int, *, threaded: bool) -> AuditLogger:
    config = LoggerConfig(
        threaded=threaded,
        fsync_interval_s=None,
        checkpoint_interval_s=1.0,
        checkpoint_key=load_signer(keys.robot_key),
        max_segment_s=5.0,
        witness=url,
        witness_timeout_s=2.0,
    )
    logger = AuditLogger(root, robot_id="amr-7", period_s=0.1, config=config)
    for i in range(cycles):
        c = logger.cycle(T0_NS + i * PERIOD_NS)
        fill_cycle(c, ("ped_close", "clear")[(i // 9) % 2])
        c.commit()
    logger.close()
    return logger


def test_the_logger_feeds_a_real_witness(
    tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]
) -> None:
    w = witness_process()
    root = tmp_path / "root"
    logger = _log(root, keys, w.url, 200, threaded=False)
    assert logger.stats.witness_cosigned > 0 and logger.stats.witness_failures == 0
    stored = read_cosigned(root, "amr-7")
    assert stored and stored[-1].tree_size == 200
    assert (
        verify(root, keys, "--witness", w.url, "--witness-key", keys.witness_verifier.vkey)[0] == 0
    )
    shortened = tmp_path / "shortened"
    shutil.copytree(root, shortened)
    sorted((shortened / "hot").glob("*.mcap"))[-1].unlink()
    shutil.rmtree(shortened / "witness")
    assert verify(shortened, keys)[0] == 0
    code, report = verify(shortened, keys, "--witness", w.url)
    assert code == 1 and [f["kind"] for f in report["findings"]] == ["truncated_tail"]


def test_a_robot_offline_is_caught_up_by_push(
    tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]
) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        down = f"http://127.0.0.1:{s.getsockname()[1]}"
    root = tmp_path / "root"
    logger = _log(root, keys, down, 120, threaded=True)
    assert logger.stats.committed == 120 and logger.stats.witness_failures > 0
    assert logger.stats.witness_cosigned == 0
    w = witness_process()
    push = run_cli("witness", "push", str(root), "--witness", w.url)
    assert push.returncode == 0, push.stdout + push.stderr
    assert read_cosigned(root, "amr-7")[-1].tree_size == 120
    assert verify(root, keys, "--witness", w.url)[0] == 0
