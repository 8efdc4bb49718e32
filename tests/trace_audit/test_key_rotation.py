"""Key rotation from the outside (profile 1.5): a robot that rotates its checkpoint key
(``AuditLogger.rotate_key``) announces the new key in its chain, signed by the old one, and
``verify --key OLD`` follows it to a CLEAN verdict, across segments and restarts, with key
files or keys in a token. Checkpoints signed by a key that was never announced (an attacker
with root who signs a rewritten or continued history with a fresh key), by a key already
rotated away from, or announced by a forged announcement are findings (exit 1)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.outside import REPO, cli
from tests.softhsm import softhsm_token
from tests.trace_audit.conftest import fill_cycle, rewrite_segment
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.records import TOPIC_CHECKPOINT
from trace_runtime.tlog.cosignature_store import read_cosigned
from trace_runtime.tlog.keys import Ed25519Signer, KeyPair, generate_keypair, load_signer
from trace_runtime.tlog.rotation import rotation_bytes
from trace_runtime.tlog.signed_note import COSIGNATURE, verifier_key

T0_NS = 1_790_000_000_000_000_000
PERIOD_NS = 100_000_000


def write(
    root: Path,
    key: str | Path,
    cycles: range,
    *,
    rotate: dict[int, str | Path] | None = None,
    witness: str | None = None,
) -> int:
    """Cycles through the real logger (5 s segments, a checkpoint a second); at each cycle
    of ``rotate`` the robot rotates to that key. Returns its failed witness submissions."""
    config = LoggerConfig(
        threaded=False,
        fsync_interval_s=None,
        checkpoint_interval_s=1.0,
        checkpoint_key=key,
        max_segment_s=5.0,
        witness=witness,
    )
    logger = AuditLogger(root, robot_id="amr-7", period_s=0.1, config=config)
    for i in cycles:
        if rotate and i in rotate:
            logger.rotate_key(rotate[i])
        c = logger.cycle(T0_NS + i * PERIOD_NS)
        fill_cycle(c, ("ped_close", "clear")[(i // 9) % 2])
        c.commit()
    logger.close()
    return logger.stats.witness_failures


def verify(root: Path, public: Path) -> tuple[int, dict[str, Any]]:
    done = cli("verify", root, "--key", public, "--json")
    assert done.returncode in (0, 1), done.stderr
    return done.returncode, json.loads(done.stdout)


def kinds(report: dict[str, Any]) -> set[str]:
    return {f["kind"] for f in report["findings"]}


@pytest.fixture
def pairs(tmp_path: Path) -> dict[str, KeyPair]:
    return {n: generate_keypair(tmp_path / "keys", name=n) for n in ("old", "new", "evil")}


def test_a_rotated_log_verifies_clean_with_the_first_key(
    tmp_path: Path, pairs: dict[str, KeyPair]
) -> None:
    root = tmp_path / "root"
    old, new = pairs["old"], pairs["new"]
    write(root, old.private_path, range(120), rotate={62: new.private_path})
    # A restart signs with the new key: the chain announced it.
    write(root, new.private_path, range(120, 160))
    code, report = verify(root, old.public_path)
    assert (code, report["findings"]) == (0, [])
    assert report["checkpoints_valid"] == report["checkpoints"] > 10
    announced = [
        c for c in checkpoints(root) if c.get("next_key") is not None
    ]  # exactly one rotation, announced in the chain under the robot's origin
    assert len(announced) == 1 and announced[0]["key_id"] == old.key_id
    raw = load_signer(new.private_path).public_key.raw
    assert announced[0]["next_key"] == verifier_key("trace.local/amr-7", raw)
    # The new key alone cannot vouch for what the old one signed before the rotation.
    assert verify(root, new.public_path)[0] == 1


def test_a_fresh_key_that_was_never_announced_is_a_finding(
    tmp_path: Path, pairs: dict[str, KeyPair]
) -> None:
    root = tmp_path / "root"
    write(root, pairs["old"].private_path, range(60))
    # Root on the robot, no access to the old key: the history goes on under a fresh key.
    write(root, pairs["evil"].private_path, range(60, 110))
    code, report = verify(root, pairs["old"].public_path)
    assert code == 1 and kinds(report) == {"key_mismatch"}
    assert all("never announced" in f["message"] for f in report["findings"])
    assert all(f["first_cycle"] >= 60 or f["last_cycle"] >= 60 for f in report["findings"])


def test_a_retired_key_no_longer_vouches(tmp_path: Path, pairs: dict[str, KeyPair]) -> None:
    root = tmp_path / "root"
    write(root, pairs["old"].private_path, range(60), rotate={30: pairs["new"].private_path})
    # The old key (maybe the stolen one, the reason for the rotation) signs again later.
    write(root, pairs["old"].private_path, range(60, 100))
    code, report = verify(root, pairs["old"].public_path)
    assert code == 1 and kinds(report) == {"key_mismatch"}
    assert all("retired by the rotation" in f["message"] for f in report["findings"])


def test_a_forged_announcement_is_a_finding(tmp_path: Path, pairs: dict[str, KeyPair]) -> None:
    """An attacker adds an announcement of their key to a checkpoint the old key signed
    (its signature does not cover the announcement), signed with their own key."""
    root = tmp_path / "root"
    write(root, pairs["old"].private_path, range(40))
    evil = load_signer(pairs["evil"].private_path)
    segment = sorted((root / "hot").glob("*.mcap"))[0]
    forged = {"done": False}

    def announce_evil(msg: RawMessage) -> bytes:
        if msg.topic != TOPIC_CHECKPOINT or forged["done"]:
            return msg.data
        forged["done"] = True
        value = orjson.loads(msg.data)
        vkey = verifier_key(value["origin"], evil.public_key.raw)
        from trace_runtime.tlog.checkpoints import decode_checkpoint

        body = rotation_bytes(decode_checkpoint(msg.data), vkey)
        value.update(next_key=vkey, next_key_signature=evil.sign(body).hex())
        return orjson.dumps(value)

    tampered = segment.with_name("tampered.tmp")
    rewrite_segment(segment, tampered, announce_evil)
    tampered.replace(segment)
    write(root, pairs["evil"].private_path, range(40, 80))
    code, report = verify(root, pairs["old"].public_path)
    assert code == 1 and forged["done"]
    messages = [f["message"] for f in report["findings"]]
    assert any("announcement of the next key does not verify" in m for m in messages), messages
    assert kinds(report) <= {"bad_signature", "key_mismatch"} and "key_mismatch" in kinds(report)


def test_rotation_through_the_token(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, pairs: dict[str, KeyPair]
) -> None:
    hsm = softhsm_token(tmp_path, monkeypatch)
    made = cli("keygen", "--out", tmp_path / "tok", "--token", hsm.uri("amr-7-2027"), "--json")
    assert made.returncode == 0, made.stderr
    root = tmp_path / "root"
    # From a key file into the token, then a restart that signs through the token.
    write(root, pairs["old"].private_path, range(50), rotate={20: hsm.uri("amr-7-2027")})
    write(root, hsm.uri("amr-7-2027"), range(50, 80))
    code, report = verify(root, pairs["old"].public_path)
    assert (code, report["findings"]) == (0, [])
    announced = [c for c in checkpoints(root) if c.get("next_key")]
    assert [c["key_id"] for c in announced] == [pairs["old"].key_id]
    after = [c for c in checkpoints(root) if c["cycle"] > announced[0]["cycle"]]
    assert after and {c["key_id"] for c in after} == {json.loads(made.stdout)["key_id"]}


def test_rotating_needs_a_key_that_can_be_announced(tmp_path: Path) -> None:
    class Blind:
        key_id = "0" * 64

        def sign(self, data: bytes) -> bytes:
            return bytes(64)

    signer = Ed25519Signer.generate()
    logger = AuditLogger(tmp_path / "root", robot_id="amr-7",
                         config=LoggerConfig(threaded=False, checkpoint_key=signer))  # fmt: skip
    from trace_runtime.errors import UsageError

    with pytest.raises(UsageError, match="public_key"):
        logger.rotate_key(Blind())
    logger.close()


def checkpoints(root: Path) -> list[dict[str, Any]]:
    """Every checkpoint of the root, read with the plain mcap reader, in file order."""
    from mcap.reader import make_reader

    found: list[dict[str, Any]] = []
    for path in sorted((root / "hot").glob("*.mcap")):
        with path.open("rb") as f:
            for _, channel, message in make_reader(f).iter_messages(topics=[TOPIC_CHECKPOINT]):
                assert channel.topic == TOPIC_CHECKPOINT
                found.append(orjson.loads(message.data))
    return found


def test_a_witnessed_rotated_log_verifies_clean(tmp_path: Path, pairs: dict[str, KeyPair]) -> None:
    """A witness given both keys of the robot (``--log`` twice, one origin) cosigns its
    checkpoints before and after the rotation, across a restart of the robot; ``verify
    --key OLD --witness local`` takes the notes signed by the announced key as the robot's."""
    origin, name = "trace.local/amr-7", "trace.local/witness"
    witness_key = generate_keypair(tmp_path / "keys", name="witness")
    w_vkey = verifier_key(name, load_signer(witness_key.private_path).public_key.raw, COSIGNATURE)
    vkeys = {n: verifier_key(origin, load_signer(pairs[n].private_path).public_key.raw)
             for n in ("old", "new")}  # fmt: skip
    root = tmp_path / "root"
    with serving(tmp_path / "state", witness_key.private_path, *vkeys.values()) as url:
        failures = write(root, pairs["old"].private_path, range(60),
                         rotate={30: pairs["new"].private_path}, witness=url)  # fmt: skip
        failures += write(root, pairs["new"].private_path, range(60, 100), witness=url)
    assert failures == 0
    assert max(c.tree_size for c in read_cosigned(root, "amr-7")) == 100
    done = cli("verify", root, "--key", pairs["old"].public_path, "--witness", "local",
               "--witness-key", w_vkey, "--json")  # fmt: skip
    report = json.loads(done.stdout)
    assert (done.returncode, report["findings"]) == (0, [])
    (robot,) = report["robots"]
    assert robot["announced_keys"] == [vkeys["new"]]


@contextlib.contextmanager
def serving(state: Path, key: Path, *log_vkeys: str) -> Iterator[str]:
    """A real ``witness serve`` process for the robot's keys; yields its URL."""
    logs = [arg for vkey in log_vkeys for arg in ("--log", vkey)]
    process = subprocess.Popen(
        [sys.executable, "-m", "trace_audit.cli", "witness", "serve", "--listen", "127.0.0.1:0",
         "--state", str(state), "--key", str(key), *logs],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    assert process.stderr is not None
    try:
        line = process.stderr.readline()
        assert "listening on " in line, line
        yield line.split("listening on ", 1)[1].split()[0]
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=20) == 0
        process.stderr.close()
