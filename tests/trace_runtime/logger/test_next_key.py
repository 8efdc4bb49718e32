"""``LoggerConfig.next_key``: a logger told to rotate does so once. It reads the key the
robot's newest checkpoint that either key signed hands on (``resume.rotated_to``): the new
key already, and it signs with it; otherwise the old key signs and announces it. A
checkpoint neither key signed (another key's, unsigned) decides nothing."""

from __future__ import annotations

from pathlib import Path

import pytest

from trace_runtime import AuditLogger, LoggerConfig, open_log
from trace_runtime.errors import UsageError
from trace_runtime.logger.resume import rotated_to
from trace_runtime.records import TOPIC_CHECKPOINT
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tlog.checkpoints import decode_checkpoint
from trace_runtime.tlog.keys import Ed25519Signer

PERIOD_NS = 100_000_000


def write(
    path: Path,
    first: int,
    cycles: int,
    key: Ed25519Signer | None,
    next_key: Ed25519Signer | None = None,
) -> None:
    """Cycles ``first``.. through a logger checkpointing every second of log time."""
    config = LoggerConfig(
        threaded=False, checkpoint_interval_s=1.0, checkpoint_key=key, next_key=next_key
    )
    logger = AuditLogger(path, robot_id="amr-1", period_s=0.1, config=config)
    for i in range(first, first + cycles):
        with logger.cycle(i * PERIOD_NS) as c:
            p, b, a, e = synthetic_cycle(i)
            c.perception(p)
            c.belief(b)
            c.action(a)
            c.execution(e)
    logger.close()


def checkpoints(path: Path) -> list[tuple[str | None, str | None]]:
    """(key id, announced verifier key) of every checkpoint, in chain order."""
    out = []
    for segment in open_log(path).segments:
        for message in segment.iter_messages():
            if message.topic == TOPIC_CHECKPOINT:
                c = decode_checkpoint(message.data)
                out.append((c.key_id, c.next_key))
    return out


@pytest.fixture
def keys() -> dict[str, Ed25519Signer]:
    return {n: Ed25519Signer.generate() for n in ("old", "new", "other")}


def test_the_rotation_is_announced_once_however_often_the_logger_starts(
    tmp_path: Path, keys: dict[str, Ed25519Signer]
) -> None:
    old, new = keys["old"], keys["new"]
    root = tmp_path / "root"
    write(root, 0, 30, old)
    assert not rotated_to(root, "amr-1", old, new.public_key)
    write(root, 30, 30, old, new)
    assert rotated_to(root, "amr-1", old, new.public_key)
    write(root, 60, 30, old, new)
    found = checkpoints(root)
    announcing = [i for i, (_, announced) in enumerate(found) if announced is not None]
    assert len(announcing) == 1  # the second run's first checkpoint
    (i,) = announcing
    assert {k for k, _ in found[: i + 1]} == {old.key_id}
    assert {k for k, _ in found[i + 1 :]} == {new.key_id} and len(found) > i + 1


def test_a_checkpoint_neither_key_signed_decides_nothing(
    tmp_path: Path, keys: dict[str, Ed25519Signer]
) -> None:
    """Newest checkpoints under another key (a misconfigured restart, an intruder's key):
    passed over; the old key's before them, which announces nothing, says "not yet"."""
    old, new, other = keys["old"], keys["new"], keys["other"]
    root = tmp_path / "root"
    write(root, 0, 30, old)
    write(root, 30, 30, other)
    assert not rotated_to(root, "amr-1", old, new.public_key)
    write(root, 60, 30, old, new)  # signs with old and announces new
    assert rotated_to(root, "amr-1", old, new.public_key)
    assert checkpoints(root)[-1][0] == new.key_id


def test_a_single_file_rotates_at_its_first_checkpoint(
    tmp_path: Path, keys: dict[str, Ed25519Signer]
) -> None:
    path = tmp_path / "run.mcap"
    write(path, 0, 30, keys["old"], keys["new"])
    found = checkpoints(path)
    assert found[0][0] == keys["old"].key_id and found[0][1] is not None
    assert {k for k, _ in found[1:]} == {keys["new"].key_id}


def test_next_key_usage_errors(tmp_path: Path, keys: dict[str, Ed25519Signer]) -> None:
    with pytest.raises(UsageError, match="needs checkpoint_key"):
        write(tmp_path / "a", 0, 1, None, keys["new"])
    with pytest.raises(UsageError, match="nothing to rotate to"):
        write(tmp_path / "b", 0, 1, keys["old"], keys["old"])
    # The writer lock was given back: the robot can start again at once.
    write(tmp_path / "b", 0, 3, keys["old"])
