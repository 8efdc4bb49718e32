"""Profile 1.2: each robot's seals are the leaves of one RFC 6962 tree, and every checkpoint
states it (``tree_size``, ``root``, ``range``) and signs it as a C2SP note.

The trees are recomputed here independently of the logger: the seals are read with the plain
``mcap`` reader, hashed with ``merkle.leaf_hash`` and folded with ``merkle.root_of``; notes
are opened with ``signed_note.open_note`` (and with Go's ``sumdb/note`` where Go is there).
"""

from __future__ import annotations

import errno
import json
import random
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from tests.trace_runtime.robot_helpers import log_cycles, spawn
from tests.trace_runtime.test_failures import _opener
from tests.trace_runtime.tlog.test_go_oracle import Ask, ask, b64, unb64  # noqa: F401 - a fixture
from tests.trace_runtime.verification.test_tamper import decode, write, write_signed_log
from trace_runtime import AuditLogger, LoggerConfig, open_log, open_segment
from trace_runtime.chain import digest
from trace_runtime.logger import checkpointer as checkpointer_module
from trace_runtime.reading.chain_tree import checkpoint_range, robot_leaves, tree_through
from trace_runtime.records import TOPIC_CHECKPOINT, TOPIC_SEAL, Checkpoint
from trace_runtime.tlog.checkpoints import (
    check_note,
    decode_checkpoint,
    encode_checkpoint,
    make_checkpoint,
)
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.merkle import CompactRange, leaf_hash, root_of
from trace_runtime.tlog.signed_note import NoteSigner, NoteVerifier, open_note, parse_checkpoint
from trace_runtime.verification import verify

PERIOD_NS = 100_000_000


def _config(signer: Ed25519Signer | None = None, **overrides: Any) -> LoggerConfig:
    fields: dict[str, Any] = {
        "threaded": False,
        "fsync_interval_s": None,
        "max_segment_s": 1.0,
        "checkpoint_interval_s": 0.3,
        "checkpoint_key": signer,
    }
    return LoggerConfig(**{**fields, **overrides})


def _plain_read(root: Path) -> tuple[list[bytes], list[Checkpoint]]:
    """Every seal's data and every checkpoint of the root's files in segment order, with
    the plain ``mcap`` reader (not trace_runtime's)."""
    seals: list[bytes] = []
    checkpoints: list[Checkpoint] = []
    files = sorted(root.glob("hot/*.mcap")) if root.is_dir() else [root]
    for path in files:
        for topic, data in _messages(path):
            if topic == TOPIC_SEAL:
                seals.append(data)
            elif topic == TOPIC_CHECKPOINT:
                checkpoints.append(Checkpoint.model_validate_json(data))
    return seals, checkpoints


def _messages(path: Path) -> list[tuple[str, bytes]]:
    """(topic, data) in file order; a file a kill left without its footer, which the plain
    reader refuses, is read by trace_runtime's scan."""
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            return [(c.topic, m.data) for _s, c, m in reader.iter_messages(log_time_order=False)]
    except Exception:
        return [(m.topic, m.data) for m in open_segment(path).iter_messages()]


def _assert_trees(root: Path, signer: Ed25519Signer | None, origin: str) -> list[Checkpoint]:
    """Every checkpoint states the tree of the seals through its head, recomputed here."""
    seals, checkpoints = _plain_read(root)
    leaves = [leaf_hash(s) for s in seals]
    position = {digest(s): i for i, s in enumerate(seals)}
    assert checkpoints
    for c in checkpoints:
        size = position[c.head] + 1
        assert c.tree_size == size, c
        assert c.root == root_of(leaves[:size]).hex()
        compact = CompactRange()
        for leaf in leaves[:size]:
            compact.append(leaf)
        assert c.range == [h.hex() for h in compact.hashes]
        assert c.origin == origin
        if signer is None:
            assert c.note is None
            continue
        assert c.note is not None
        opened = open_note(c.note, [NoteVerifier.of(origin, signer.public_key.raw)])
        body = parse_checkpoint(opened.text)
        assert (body.origin, body.size, body.root.hex()) == (origin, c.tree_size, c.root)
        assert check_note(c, signer.public_key) == "valid"
    return checkpoints


def test_checkpoints_carry_the_tree_across_rotation_and_a_restart(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="amr-1", config=_config(signer)) as logger:
        log_cycles(logger, range(25))
    with AuditLogger(root, robot_id="amr-1", config=_config(signer)) as logger:
        log_cycles(logger, range(25, 47))
    assert logger.stats.tree_failures == 0
    assert len(list(root.glob("hot/*.mcap"))) >= 5
    checkpoints = _assert_trees(root, signer, "trace.local/amr-1")
    assert checkpoints[-1].tree_size == 47 and checkpoints[-1].final
    report = verify(open_log(root), key=signer.public_key)
    assert report.ok and report.checkpoints_valid == report.checkpoints == len(checkpoints)
    log = open_log(root)
    assert root_of(robot_leaves(log, "amr-1")).hex() == checkpoints[-1].root


def test_the_origin_is_configurable_and_a_dropped_batch_leaves_no_leaf(tmp_path: Path) -> None:
    """Failed writes drop their cycles: those have no seal on disk, so no leaf."""
    signer = Ed25519Signer.generate()
    state: dict[str, Any] = {"failing": False, "errno": errno.ENOSPC}
    path = tmp_path / "run.mcap"
    config = _config(signer, origin="fleet.example/amr-7", opener=_opener(state))
    logger = AuditLogger(path, robot_id="amr-7", config=config)
    for i in range(30):
        state["failing"] = i in {4, 5, 11, 17}
        log_cycles(logger, range(i, i + 1))
    state["failing"] = False
    logger.close()
    assert logger.stats.dropped_io == 4
    checkpoints = _assert_trees(path, signer, "fleet.example/amr-7")
    assert checkpoints[-1].tree_size == 26
    assert verify(open_log(path), key=signer.public_key).ok


def test_a_bad_origin_is_a_set_up_error(tmp_path: Path) -> None:
    with pytest.raises(Exception, match="origin"):
        AuditLogger(tmp_path / "r.mcap", robot_id="r", config=_config(origin="has space"))


def test_unsigned_checkpoints_carry_the_tree_without_a_note(tmp_path: Path) -> None:
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="r", config=_config()) as logger:
        log_cycles(logger, range(12))
    _assert_trees(root, None, "trace.local/r")


KILLED_ROBOT = """
    import sys, time
    from trace_runtime import AuditLogger, LoggerConfig
    from trace_runtime.testing import synthetic_cycle
    config = LoggerConfig(
        threaded=False, fsync_interval_s=0.0, checkpoint_interval_s=0.5,
        max_segment_s=1.0, checkpoint_key=sys.argv[2],
    )
    log = AuditLogger(sys.argv[1], robot_id="r", config=config)
    for i in range(int(sys.argv[3])):
        p, b, a, e = synthetic_cycle(i)
        log.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    print("ready", flush=True)
    time.sleep(60)
"""


def test_the_tree_resumes_after_a_logger_is_killed(tmp_path: Path) -> None:
    """kill -9 mid-segment: seals after the segment's last checkpoint, no final one. The
    next logger resumes the tree from that checkpoint's range plus those seals."""
    signer = Ed25519Signer.generate()
    key = tmp_path / "robot.key"
    key.write_bytes(signer.private_pem())
    root = tmp_path / "root"
    proc = spawn(KILLED_ROBOT, str(root), str(key), "17")
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "ready", proc.stderr
    finally:
        proc.kill()  # SIGKILL: no close, no final checkpoint
        proc.wait(10)
        for stream in (proc.stdout, proc.stderr):
            if stream is not None:
                stream.close()
    seals, checkpoints = _plain_read(root)
    assert len(seals) == 17 and checkpoints[-1].tree_size is not None
    assert checkpoints[-1].tree_size < 17 and not checkpoints[-1].final
    resumed = tree_through(root, "r", digest(seals[-1]))
    assert resumed is not None and resumed.root() == root_of(leaf_hash(s) for s in seals)
    with AuditLogger(root, robot_id="r", config=_config(signer)) as logger:
        log_cycles(logger, range(17, 40))
    assert logger.stats.tree_failures == 0
    checkpoints = _assert_trees(root, signer, "trace.local/r")
    assert checkpoints[-1].tree_size == 40
    report = verify(open_log(root), key=signer.public_key)
    assert report.ok, report.findings


def test_a_chain_without_a_tree_checkpoint_is_recomputed_from_all_its_seals(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A root written before profile 1.2 (checkpoints without a tree): the next logger's
    tree covers every seal from genesis, and verify checks it from there."""
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"

    def old_profile(**fields: Any) -> Checkpoint:
        for name in ("tree", "origin", "note_signer"):
            fields.pop(name, None)
        return make_checkpoint(**fields)

    with monkeypatch.context() as patched:
        patched.setattr(checkpointer_module, "make_checkpoint", old_profile)
        with AuditLogger(root, robot_id="r", config=_config(signer)) as logger:
            log_cycles(logger, range(23))
    seals, old = _plain_read(root)
    assert old and all(c.tree_size is None and c.note is None for c in old)
    with AuditLogger(root, robot_id="r", config=_config(signer)) as logger:
        log_cycles(logger, range(23, 35))
    seals, checkpoints = _plain_read(root)
    new = [c for c in checkpoints if c.tree_size is not None]
    assert new and new[0].tree_size == new[0].cycle + 1 == 27
    assert new[-1].root == root_of(leaf_hash(s) for s in seals).hex()
    report = verify(open_log(root), key=signer.public_key)
    assert report.ok, report.findings


# --- verify ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def signed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Ed25519Signer]:
    signer = Ed25519Signer.generate()
    path = tmp_path_factory.mktemp("tree") / "amr-7.mcap"
    write_signed_log(path, signer, 40, interval_s=0.5)
    return path, signer


def _rewrite_checkpoint(
    source: Path, target: Path, change: Any, which: int = 2
) -> tuple[Checkpoint, Checkpoint]:
    """Rewrite the ``which``-th checkpoint of ``source`` with ``change(checkpoint)``."""
    decoded = decode(source)
    unit = decoded.units[decoded.checkpoints()[which]]
    (message,) = unit.messages
    before = decode_checkpoint(message.data)
    after = change(before)
    unit.messages[0] = replace(message, data=encode_checkpoint(after))
    write(decoded, target, random.Random(1))
    return before, after


def _findings(path: Path, signer: Ed25519Signer | None) -> list[tuple[str, int | None]]:
    report = verify(open_log(path), key=None if signer is None else signer.public_key)
    return [(f.kind, f.where.first_cycle) for f in report.findings]


def test_a_clean_rewrite_verifies_and_states_the_tree(
    signed: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    path, signer = signed
    _assert_trees(path, signer, "trace.local/amr-7")
    copy = tmp_path / "copy.mcap"
    _rewrite_checkpoint(path, copy, lambda c: c)
    assert _findings(copy, signer) == [] and _findings(copy, None) == []


def test_a_root_rewritten_without_the_key_is_a_tree_mismatch(
    signed: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    """The head signature (trace-checkpoint/1) does not cover the tree: the recomputed tree
    and the note do."""
    path, signer = signed
    target = tmp_path / "root.mcap"
    before, after = _rewrite_checkpoint(
        path, target, lambda c: c.model_copy(update={"root": "ab" * 32})
    )
    assert check_note(after, signer.public_key) == "mismatch"
    for key in (None, signer):
        found = _findings(target, key)
        assert ("tree_mismatch", before.cycle) in found, found
    report = verify(open_log(target), key=signer.public_key)
    assert report.checkpoints_valid == report.checkpoints - 1


def test_a_tree_resigned_with_another_key_is_found(
    signed: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    """An attacker states another tree, consistent with itself and signed under the origin
    with their own key: the seals give another root, and the key is not the robot's."""
    path, signer = signed
    attacker = Ed25519Signer.generate()
    forged = CompactRange()
    for i in range(7):
        forged.append(leaf_hash(b"forged %d" % i))

    def resign(c: Checkpoint) -> Checkpoint:
        assert c.origin is not None
        note_signer = NoteSigner(c.origin, attacker, attacker.public_key.raw)
        fields = c.model_dump(exclude={"key_id", "signature", "tree_size", "root", "range", "note"})
        return make_checkpoint(signer=signer, tree=forged, note_signer=note_signer, **fields)

    before, after = _rewrite_checkpoint(path, tmp_path / "resigned.mcap", resign)
    assert checkpoint_range(after) is not None  # consistent with itself
    assert ("tree_mismatch", before.cycle) in _findings(tmp_path / "resigned.mcap", None)
    found = _findings(tmp_path / "resigned.mcap", signer)
    assert ("key_mismatch", before.cycle) in found and ("tree_mismatch", before.cycle) in found


def test_a_changed_seal_is_a_finding(signed: tuple[Path, Ed25519Signer], tmp_path: Path) -> None:
    path, signer = signed
    decoded = decode(path)
    unit = decoded.units[decoded.cycles()[9]]
    seal = unit.messages[-1]
    value = json.loads(seal.data)
    value["dropped"] = value.get("dropped", 0) + 1
    unit.messages[-1] = replace(seal, data=json.dumps(value, separators=(",", ":")).encode())
    target = tmp_path / "seal.mcap"
    write(decoded, target, random.Random(2))
    report = verify(open_log(target), key=signer.public_key)
    assert not report.ok
    assert any(f.covers(unit.cycle) for f in report.findings)


def test_an_old_profile_log_verifies_as_before(
    signed: tuple[Path, Ed25519Signer], tmp_path: Path
) -> None:
    """Checkpoints without their tree (profile 1.1), re-signed: clean, nothing about trees."""
    path, signer = signed
    decoded = decode(path)
    for index in decoded.checkpoints():
        (message,) = decoded.units[index].messages
        c = decode_checkpoint(message.data)
        fields = c.model_dump(
            exclude={"key_id", "signature", "tree_size", "root", "range", "origin", "note"}
        )
        old = make_checkpoint(signer=signer, **fields)
        decoded.units[index].messages[0] = replace(message, data=encode_checkpoint(old))
    target = tmp_path / "old.mcap"
    write(decoded, target, random.Random(3))
    report = verify(open_log(target), key=signer.public_key)
    assert report.ok and report.checkpoints_valid == report.checkpoints


def test_a_log_starting_after_genesis_takes_the_tree_from_its_first_checkpoint(
    tmp_path: Path,
) -> None:
    """Retention removed the first segments: verify continues from the first checkpoint's
    range and still finds a root rewritten later."""
    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="r", config=_config(signer)) as logger:
        log_cycles(logger, range(45))
    files = sorted(root.glob("hot/*.mcap"))
    for old in files[:2]:
        old.unlink()
    assert verify(open_log(root), key=signer.public_key).ok
    victim = files[-1]
    decoded = decode(victim)
    unit = decoded.units[decoded.checkpoints()[-1]]
    (message,) = unit.messages
    c = decode_checkpoint(message.data)
    unit.messages[0] = replace(
        message, data=encode_checkpoint(c.model_copy(update={"tree_size": 3}))
    )
    write(decoded, victim, random.Random(4))
    found = [(f.kind, f.where.first_cycle) for f in verify(open_log(root)).findings]
    assert ("tree_mismatch", c.cycle) in found


# --- the reference implementation ------------------------------------------------------------


def test_go_opens_the_notes_and_hashes_the_same_tree(
    signed: tuple[Path, Ed25519Signer],
    ask: Ask,  # noqa: F811 - the oracle fixture
) -> None:
    path, signer = signed
    seals, checkpoints = _plain_read(path)
    origin = checkpoints[0].origin
    assert origin is not None
    vkey = NoteVerifier.of(origin, signer.public_key.raw).vkey
    answer = ask(
        {
            "open": [{"note": c.note, "vkeys": [vkey]} for c in checkpoints],
            "leaves": [b64(s) for s in seals],
            "roots": [c.tree_size for c in checkpoints],
        }
    )
    for opened, c in zip(answer["open"], checkpoints, strict=True):
        assert opened["error"] == "", opened
        body = parse_checkpoint(opened["text"])
        assert (body.origin, body.size, body.root.hex()) == (origin, c.tree_size, c.root)
    assert [unb64(r).hex() for r in answer["roots"]] == [c.root for c in checkpoints]
    assert [unb64(h) for h in answer["record_hashes"]] == [leaf_hash(s) for s in seals]


def test_a_tree_that_cannot_be_resumed_leaves_checkpoints_without_one(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The chain on disk cannot be followed to its last seal: the logger still logs, its
    checkpoints carry no tree, the stats count them, and verify finds nothing to object."""
    from trace_runtime.logger import resume

    signer = Ed25519Signer.generate()
    root = tmp_path / "root"
    with AuditLogger(root, robot_id="r", config=_config(signer)) as logger:
        log_cycles(logger, range(8))
    monkeypatch.setattr(resume, "tree_through", lambda *_: None)
    with AuditLogger(root, robot_id="r", config=_config(signer)) as logger:
        log_cycles(logger, range(8, 20))
    assert logger.stats.tree_failures == logger.stats.checkpoints > 0
    _seals, checkpoints = _plain_read(root)
    assert checkpoints[-1].tree_size is None and checkpoints[-1].signature is not None
    assert verify(open_log(root), key=signer.public_key).ok


def test_a_consistency_proof_from_the_old_range_and_the_new_leaves_is_the_rfcs() -> None:
    """What a logger keeps for its witness (the range at the witness's size and the leaves
    since) proves every old size against every new one, as the full leaf list does."""
    from trace_runtime.reading.chain_tree import consistency_proof_from
    from trace_runtime.tlog.merkle import consistency_proof

    leaves = [leaf_hash(b"seal %d" % i) for i in range(90)]
    for n in range(91):
        for m in range(n + 1):
            old = CompactRange()
            for leaf in leaves[:m]:
                old.append(leaf)
            assert consistency_proof_from(old, leaves[m:n]) == consistency_proof(m, leaves[:n])
