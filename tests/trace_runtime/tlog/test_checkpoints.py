"""Checkpoints: the signed bytes, signature states, and the logger's checkpoint hook.

Key files are tested in test_keys.py, the per-cycle seal check in test_seal_check.py."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from trace_runtime import AuditLogger, LoggerConfig, open_log, open_segment
from trace_runtime.chain import digest
from trace_runtime.encoding.seal_check import verify_cycle
from trace_runtime.errors import UsageError
from trace_runtime.records import GENESIS, TOPIC_SEAL, Checkpoint
from trace_runtime.testing import simulate_crash, synthetic_cycle
from trace_runtime.tlog.checkpoints import (
    check_checkpoint,
    decode_checkpoint,
    iter_checkpoints,
    make_checkpoint,
    signing_bytes,
)
from trace_runtime.tlog.keys import Ed25519Signer, generate_keypair, load_public_key

PERIOD_NS = 100_000_000


def _write(path: Path, cycles: int, config: LoggerConfig, *, start: int = 0) -> AuditLogger:
    logger = AuditLogger(path, robot_id="amr-1", period_s=0.1, config=config)
    for i in range(start, start + cycles):
        with logger.cycle(i * PERIOD_NS) as c:
            ref = c.sensor("/sensors/lidar", {"ranges": [1.0 + i / 100, 2.0]})
            p, b, a, e = synthetic_cycle(i)
            entity = p.entities[0]
            evidence = replace_ref(entity.evidence[0], ref)
            c.perception(
                p.model_copy(
                    update={"entities": [entity.model_copy(update={"evidence": [evidence]})]}
                )
            )
            c.belief(b)
            c.action(a)
            c.execution(e)
    logger.close()
    return logger


def replace_ref(evidence: object, ref: object) -> object:
    return evidence.model_copy(update={"ref": ref})  # type: ignore[attr-defined]


def _sync(**kw: object) -> LoggerConfig:
    return LoggerConfig(threaded=False, fsync_interval_s=None, **kw)  # type: ignore[arg-type]


def _checkpoints(path: Path) -> list[Checkpoint]:
    return [decode_checkpoint(m.data) for m in iter_checkpoints(open_segment(path))]


# --- checkpoints and signatures ---------------------------------------------------------------


GOLDEN = Checkpoint(
    cycle=41,
    t_ns=4_100_000_000,
    robot_id="amr-7",
    segment=2,
    first_cycle=36,
    sealed=6,
    head="ab" * 32,
    final=True,
    key_id="cd" * 32,
)


def test_signing_bytes_are_the_documented_lines() -> None:
    """docs/integrity.md specifies these bytes; another language must produce them too."""
    assert signing_bytes(GOLDEN) == (
        b"trace-checkpoint/1\n"
        b"robot_id=amr-7\n"
        b"segment=2\n"
        b"first_cycle=36\n"
        b"cycle=41\n"
        b"t_ns=4100000000\n"
        b"sealed=6\n"
        b"head=" + b"ab" * 32 + b"\n"
        b"final=true\n"
        b"key_id=" + b"cd" * 32 + b"\n"
    )
    unsigned = GOLDEN.model_copy(update={"key_id": None, "final": False})
    assert signing_bytes(unsigned).endswith(b"final=false\nkey_id=\n")


def test_a_signature_checks_out_with_the_documented_recipe_alone() -> None:
    """Verify with nothing but the docs: rebuild the lines from the JSON, check Ed25519."""
    signer = Ed25519Signer.generate()
    fields = GOLDEN.model_dump(exclude={"key_id", "signature"})
    checkpoint = make_checkpoint(signer=signer, **fields)
    import json

    doc = json.loads(checkpoint.model_dump_json())
    lines = [
        "trace-checkpoint/1",
        *(
            f"{name}={str(doc[name]).lower() if name == 'final' else doc[name]}"
            for name in (
                "robot_id",
                "segment",
                "first_cycle",
                "cycle",
                "t_ns",
                "sealed",
                "head",
                "final",
                "key_id",
            )
        ),
    ]
    message = ("\n".join(lines) + "\n").encode()
    Ed25519PublicKey.from_public_bytes(signer.public_key.raw).verify(
        bytes.fromhex(doc["signature"]), message
    )


def test_checkpoint_states() -> None:
    robot, other = Ed25519Signer.generate(), Ed25519Signer.generate()
    fields = GOLDEN.model_dump(exclude={"key_id", "signature"})
    signed = make_checkpoint(signer=robot, **fields)
    key = robot.public_key
    assert check_checkpoint(signed, key) == "valid"
    assert check_checkpoint(signed, None) == "unchecked"
    assert check_checkpoint(make_checkpoint(**fields), key) == "unsigned"
    assert check_checkpoint(make_checkpoint(signer=other, **fields), key) == "key_mismatch"
    altered = signed.model_copy(update={"sealed": signed.sealed + 1})
    assert check_checkpoint(altered, key) == "bad_signature"
    garbled = signed.model_copy(update={"signature": "zz"})
    assert check_checkpoint(garbled, key) == "bad_signature"


# --- the logger's checkpoints -------------------------------------------------------------------


def test_checkpoints_every_interval_of_log_time_and_at_close(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    path = tmp_path / "run.mcap"
    logger = _write(path, 95, _sync(checkpoint_interval_s=2.0, checkpoint_key=signer))
    checkpoints = _checkpoints(path)
    assert [c.cycle for c in checkpoints] == [20, 40, 60, 80, 94]
    assert [c.final for c in checkpoints] == [False] * 4 + [True]
    assert [c.sealed for c in checkpoints] == [21, 41, 61, 81, 95]
    assert logger.stats.checkpoints == 5 and logger.stats.checkpoint_failures == 0
    seals = {c.cycle: digest(c.payloads[TOPIC_SEAL]) for c in open_log(path).iter_cycles()}
    for c in checkpoints:
        assert c.head == seals[c.cycle] and c.t_ns == c.cycle * PERIOD_NS
        assert check_checkpoint(c, signer.public_key) == "valid"


def test_unsigned_checkpoints_without_a_key_and_none_between_without_an_interval(
    tmp_path: Path,
) -> None:
    path = tmp_path / "run.mcap"
    _write(path, 30, _sync(checkpoint_interval_s=None))
    (only,) = _checkpoints(path)
    assert only.final and only.cycle == 29 and only.signature is None and only.key_id is None


def test_every_rotated_segment_is_closed_by_its_own_checkpoint(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    _write(root, 50, _sync(max_segment_s=2.0, checkpoint_interval_s=1.0, checkpoint_key=signer))
    segments = sorted((root / "hot").glob("*.mcap"))
    assert len(segments) == 3
    for number, path in enumerate(segments):
        checkpoints = _checkpoints(path)
        session = open_segment(path).session
        assert checkpoints[-1].final and all(c.segment == number for c in checkpoints)
        assert all(c.first_cycle == session.first_cycle for c in checkpoints)
        last = [c for c in open_segment(path).iter_cycles()][-1]
        assert checkpoints[-1].cycle == last.cycle
        assert checkpoints[-1].sealed == last.cycle - session.first_cycle + 1


def test_a_threaded_logger_writes_checkpoints_too(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    config = LoggerConfig(fsync_interval_s=None, checkpoint_interval_s=1.0)
    _write(path, 40, config)
    checkpoints = _checkpoints(path)
    assert checkpoints[-1].final and checkpoints[-1].cycle == 39
    # Checkpoints follow whole batches, whose size depends on timing; the interval holds.
    periodic = [c.t_ns for c in checkpoints[:-1]]
    assert all(b - a >= 1_000_000_000 for a, b in itertools.pairwise(periodic))
    seals = {c.cycle: digest(c.payloads[TOPIC_SEAL]) for c in open_log(path).iter_cycles()}
    assert all(c.head == seals[c.cycle] for c in checkpoints)


class _BrokenSigner:
    key_id = "ff" * 32

    def sign(self, data: bytes) -> bytes:
        raise RuntimeError("the HSM went away")


def test_a_failing_signer_never_reaches_the_control_loop(tmp_path: Path) -> None:
    """Signing fails: the cycles are all written, checkpoints go out unsigned, asked rarely."""
    path = tmp_path / "run.mcap"
    logger = _write(path, 30, _sync(checkpoint_interval_s=1.0, checkpoint_key=_BrokenSigner()))
    assert logger.stats.written == 30 and logger.stats.dropped == 0
    # Tried once a second of log time (at 1.0, 2.0 s) and at close; never on every cycle.
    assert logger.stats.checkpoints == 3 and logger.stats.checkpoint_failures == 3
    checkpoints = _checkpoints(path)
    assert [(c.cycle, c.final, c.signature) for c in checkpoints] == [
        (10, False, None),
        (20, False, None),
        (29, True, None),
    ]
    prev = GENESIS
    for cycle in open_log(path).iter_cycles():
        status = verify_cycle(cycle, prev)
        assert status.state == "verified" and status.link == "ok"
        prev = status.seal_digest or ""


def test_a_bad_key_file_fails_at_set_up_before_any_file_is_written(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with pytest.raises(UsageError, match="no such file"):
        AuditLogger(path, robot_id="amr-1", config=_sync(checkpoint_key=tmp_path / "none.key"))
    assert not path.exists()
    with pytest.raises(UsageError, match="checkpoint_interval_s"):
        AuditLogger(path, robot_id="amr-1", config=_sync(checkpoint_interval_s=0))


def test_a_key_path_in_the_config_signs(tmp_path: Path) -> None:
    pair = generate_keypair(tmp_path / "keys")
    path = tmp_path / "run.mcap"
    _write(path, 12, _sync(checkpoint_key=str(pair.private_path)))
    (final,) = _checkpoints(path)
    assert check_checkpoint(final, load_public_key(pair.public_path)) == "valid"


def test_a_restart_after_a_crash_before_the_first_write_continues_the_chain(
    tmp_path: Path,
) -> None:
    """A segment killed before its first write has no seal; the next run skips over it."""
    root = tmp_path / "root"
    _write(root, 10, _sync())
    crashed = AuditLogger(root, robot_id="amr-1", config=_sync())
    assert crashed._segment is not None
    simulate_crash(crashed)  # killed: no closing checkpoint, no summary
    _write(root, 5, _sync(), start=10)
    segments = sorted((root / "hot").glob("*.mcap"))
    assert len(segments) == 3
    third = open_segment(segments[2])
    assert third.session.first_cycle == 10
    last_of_first = list(open_segment(segments[0]).iter_cycles())[-1]
    assert third.session.prev_seal == digest(last_of_first.payloads[TOPIC_SEAL])
