"""The logger submits its checkpoints to a C2SP tlog-witness from the writer thread: each
cosigned note is stored beside the log, a witness that is down or elsewhere costs counted
failures and is caught up with the next checkpoint, and the control loop never waits.

The witness is ``trace-audit witness serve``'s own (``trace_audit.witness.server``), run in
this process on a free localhost port.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from http.server import ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from tests.trace_runtime.robot_helpers import log_cycles
from trace_audit.witness.server import Witness, _handler
from trace_audit.witness.state import WitnessState
from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.reading.chain_tree import robot_leaves
from trace_runtime.tlog.cosignature_store import read_cosigned
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.merkle import root_of
from trace_runtime.tlog.signed_note import (
    COSIGNATURE,
    NoteSigner,
    NoteVerifier,
    open_note,
    parse_checkpoint,
)

ORIGIN = "trace.local/amr-1"


class LocalWitness:
    """A witness serving on 127.0.0.1:``port`` in a thread, until ``stop``."""

    def __init__(self, state: Path, robot: Ed25519Signer, port: int = 0) -> None:
        key = Ed25519Signer.generate()
        self.cosigner = NoteSigner("witness.test/w1", key, key.public_key.raw, COSIGNATURE)
        self.state = WitnessState(state)
        log = NoteVerifier.of(ORIGIN, robot.public_key.raw)
        witness = Witness(self.cosigner, [log], self.state)
        self.httpd = ThreadingHTTPServer(("127.0.0.1", port), _handler(witness, None))
        self.httpd.daemon_threads = True
        self.port = int(self.httpd.server_address[1])
        self.url = f"http://127.0.0.1:{self.port}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    def size(self) -> int:
        latest = self.state.latest(ORIGIN)
        return 0 if latest is None else int(latest.tree_size)

    def stop(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        self.state.close()


@pytest.fixture
def robot() -> Ed25519Signer:
    return Ed25519Signer.generate()


@pytest.fixture
def witness(tmp_path: Path, robot: Ed25519Signer) -> Iterator[LocalWitness]:
    running = LocalWitness(tmp_path / "witness-state", robot)
    yield running
    running.stop()


def _config(robot: Ed25519Signer, url: str, **overrides: Any) -> LoggerConfig:
    fields: dict[str, Any] = {
        "threaded": False,
        "fsync_interval_s": None,
        "max_segment_s": 1.0,
        "checkpoint_interval_s": 0.3,
        "checkpoint_key": robot,
        "witness": url,
        "witness_timeout_s": 2.0,
    }
    return LoggerConfig(**{**fields, **overrides})


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _assert_store(root: Path, robot: Ed25519Signer, witness: LocalWitness) -> None:
    """Every stored note is the robot's checkpoint, cosigned by the witness, of the tree
    over the log's seals at its size."""
    stored = read_cosigned(root, "amr-1")
    assert stored
    leaves = robot_leaves(open_log(root), "amr-1")
    for record in stored:
        opened = open_note(
            record.note,
            [NoteVerifier.of(ORIGIN, robot.public_key.raw), witness.cosigner.verifier],
        )
        assert len(opened.verified) == 2
        body = parse_checkpoint(opened.text)
        assert body.root == root_of(leaves[: body.size]) and record.tree_size == body.size
    assert stored[-1].tree_size == witness.size() == len(leaves)


def test_the_writer_thread_submits_every_checkpoint_and_stores_the_cosignatures(
    tmp_path: Path, robot: Ed25519Signer, witness: LocalWitness
) -> None:
    """Threaded: the writer submits the newest checkpoint of each batch it wrote."""
    root = tmp_path / "root"
    config = _config(robot, witness.url, threaded=True)
    with AuditLogger(root, robot_id="amr-1", config=config) as logger:
        log_cycles(logger, range(30))
    stats = logger.stats
    assert stats.witness_failures == 0 and stats.witness_cosigned >= 1
    _assert_store(root, robot, witness)


def test_each_checkpoint_is_cosigned_in_turn(
    tmp_path: Path, robot: Ed25519Signer, witness: LocalWitness
) -> None:
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="amr-1", config=_config(robot, witness.url)) as logger:
        log_cycles(logger, range(30))
    stats = logger.stats
    assert stats.witness_failures == 0 and stats.witness_cosigned == stats.checkpoints
    assert len(read_cosigned(root, "amr-1")) == stats.checkpoints
    _assert_store(root, robot, witness)


def test_a_restarted_logger_goes_on_from_where_the_witness_is(
    tmp_path: Path, robot: Ed25519Signer, witness: LocalWitness
) -> None:
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="amr-1", config=_config(robot, witness.url)) as logger:
        log_cycles(logger, range(14))
    with AuditLogger(root, robot_id="amr-1", config=_config(robot, witness.url)) as logger:
        log_cycles(logger, range(14, 33))
    assert logger.stats.witness_failures == 0
    _assert_store(root, robot, witness)


def test_a_witness_that_knows_another_size_is_learnt_from_its_409(
    tmp_path: Path, robot: Ed25519Signer, witness: LocalWitness
) -> None:
    """The root was logged without the witness; a restarted logger takes the witness to be
    at its own size, the witness (at 0) answers 409, the next checkpoint is proved from 0."""
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="amr-1", config=_config(robot, "")) as logger:
        log_cycles(logger, range(12))
    with AuditLogger(root, robot_id="amr-1", config=_config(robot, witness.url)) as logger:
        log_cycles(logger, range(12, 30))
    assert logger.stats.witness_failures == 1 and logger.stats.witness_cosigned >= 3
    _assert_store(root, robot, witness)


def test_a_witness_that_is_down_costs_counted_failures_then_catches_up(
    tmp_path: Path, robot: Ed25519Signer
) -> None:
    port = _free_port()
    root = tmp_path / "root"
    url = f"http://127.0.0.1:{port}"
    logger = AuditLogger(root, robot_id="amr-1", config=_config(robot, url, threaded=False))
    log_cycles(logger, range(15))
    assert logger.stats.witness_failures >= 3 and logger.stats.witness_cosigned == 0
    assert logger.stats.written == 15 and logger.stats.dropped == 0
    witness = LocalWitness(tmp_path / "witness-state", robot, port)
    try:
        log_cycles(logger, range(15, 30))
        logger.close()
        assert logger.stats.witness_cosigned >= 3
        _assert_store(root, robot, witness)
    finally:
        witness.stop()


def test_no_witness_without_signed_notes(tmp_path: Path, witness: LocalWitness) -> None:
    root = tmp_path / "root"
    config = LoggerConfig(threaded=False, checkpoint_interval_s=0.3, witness=witness.url)
    with AuditLogger(root, robot_id="amr-1", config=config) as logger:
        log_cycles(logger, range(10))
    assert logger.stats.witness_cosigned == 0 and witness.size() == 0
