"""Proof bundles: one cycle of a real logger root, proved to a signed and cosigned checkpoint
and checked without the log; every byte of the bundle changed makes it fail."""

from __future__ import annotations

import base64
import json
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.outside import cli, one_line
from tests.trace_audit.witness.conftest import Keys, WitnessProcess, run_cli
from tests.trace_audit.witness.test_tail import write
from trace_audit.proof import BUNDLE_FORMAT, check_bundle
from trace_runtime import AuditLogger
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tlog.keys import load_public_key
from trace_runtime.tlog.tlog_proof import parse_tlog_proof


@pytest.fixture
def proved(
    tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]
) -> tuple[Path, Path]:
    root = tmp_path / "root"
    write(root, keys.robot_key, range(120))
    w = witness_process()
    assert run_cli("witness", "push", str(root), "--witness", w.url).returncode == 0
    bundle = tmp_path / "cycle-37.json"
    made = run_cli("prove", str(root), "--cycle", "37", "--out", str(bundle))
    assert made.returncode == 0, made.stderr
    assert "signed and cosigned" in made.stdout
    return root, bundle


def test_a_bundle_verifies_without_the_log(proved: tuple[Path, Path], keys: Keys) -> None:
    root, bundle = proved
    data = json.loads(bundle.read_text())
    assert data["format"] == BUNDLE_FORMAT and data["cycle"] == 37 and data["cosigned"]
    assert data["leaf_index"] == 37 and data["tree_size"] > 37
    [reading] = data["sensors"]  # the cycle's one LiDAR scan, covered by its 1.3 seal
    assert (reading["topic"], reading["log_time_ns"]) == ("/sensors/lidar", data["t_ns"])
    moved = bundle.parent / "elsewhere.json"
    moved.write_bytes(bundle.read_bytes())
    import shutil

    shutil.rmtree(root)
    vkey = keys.witness_verifier.vkey
    done = run_cli("verify-proof", str(moved), "--key", str(keys.robot_pub), "--witness-key", vkey,
                   "--plain")  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "VERIFIED" in done.stdout and "no later than" in done.stdout
    assert "1 sensor reading(s) match the seal" in done.stdout
    wrong_key = run_cli("verify-proof", str(moved), "--key", str(keys.witness_pub))
    assert wrong_key.returncode == 1
    assert run_cli("verify-proof", str(root / "nothing.json"), "--key", str(keys.robot_pub)
                   ).returncode == 3  # fmt: skip


def test_every_byte_changed_fails(proved: tuple[Path, Path], keys: Keys) -> None:
    _root, bundle = proved
    original = bundle.read_bytes()
    key = load_public_key(keys.robot_pub)
    witness = keys.witness_verifier

    def verifies(data: bytes) -> bool:
        try:
            value = orjson.loads(data)
        except orjson.JSONDecodeError:
            return False
        if not isinstance(value, dict) or value.get("format") != BUNDLE_FORMAT:
            return False
        return check_bundle(value, key, witness_key=witness).ok

    assert verifies(original)
    passed = []
    for i in range(len(original)):
        for flip in (0x01, 0x20):
            changed = bytearray(original)
            changed[i] ^= flip
            if verifies(bytes(changed)):
                passed.append((i, flip, original[max(0, i - 20) : i + 20]))
    assert not passed, passed[:5]


def _plain(bundle: dict[str, Any]) -> dict[str, Any]:
    """The bundle with each message's and reading's data as base64 of the bytes themselves
    (trace-proof/1 and /2), inflated from the raw DEFLATE streams of /3."""

    def inflated(item: dict[str, Any]) -> dict[str, Any]:
        data = zlib.decompress(base64.b64decode(item["data"]), -15)
        return {**item, "data": base64.b64encode(data).decode()}

    return {
        **bundle,
        "messages": [inflated(m) for m in bundle["messages"]],
        "sensors": [inflated(m) for m in bundle["sensors"]],
    }


def _fourth(bundle: dict[str, Any]) -> dict[str, Any]:
    """A ``trace-proof/5`` bundle as ``/4`` wrote it: the inclusion proof and the note as
    fields of their own, not one tlog-proof text, and no key rotations."""
    proof = parse_tlog_proof(bundle["tlog_proof"])
    fields = {k: v for k, v in bundle.items() if k not in ("tlog_proof", "key_rotations")}
    inclusion = [base64.b64encode(h).decode() for h in proof.hashes]
    return fields | {"format": "trace-proof/4", "inclusion": inclusion, "note": proof.note}


def test_bundles_of_the_earlier_formats_still_verify(proved: tuple[Path, Path], keys: Keys) -> None:
    """``trace-proof/1`` (before the readings were carried), ``/2`` (before the data was
    deflated), ``/3`` (before recording messages were carried) and ``/4`` (before the
    inclusion proof was a C2SP tlog-proof) are checked as before; /1's readings are simply
    not there to check."""
    _root, bundle = proved
    key, witness = load_public_key(keys.robot_pub), keys.witness_verifier
    data = _fourth(json.loads(bundle.read_text()))
    assert check_bundle(data, key, witness_key=witness).ok
    assert not check_bundle({**data, "format": BUNDLE_FORMAT}, key, witness_key=witness).ok
    third = {k: v for k, v in data.items() if k != "recorded"} | {"format": "trace-proof/3"}
    assert check_bundle(third, key, witness_key=witness).ok  # before recordings were carried
    second = _plain(third) | {"format": "trace-proof/2"}
    assert check_bundle(second, key, witness_key=witness).ok
    assert not check_bundle({**data, "format": "trace-proof/2"}, key, witness_key=witness).ok
    old = {k: v for k, v in second.items() if k != "sensors"} | {"format": "trace-proof/1"}
    checked = check_bundle(old, key, witness_key=witness)
    assert checked.ok and "sensors" not in [name for name, _ok, _detail in checked.steps]
    mixed = {**second, "format": "trace-proof/1"}  # a /1 bundle with a field /1 does not have
    assert not check_bundle(mixed, key, witness_key=witness).ok
    quiet = {**data, "sensors": []}  # the reading left out: the seal counts one
    assert not check_bundle(quiet, key, witness_key=witness).ok


def _rewrap(bundle: dict[str, Any], topic: str, stream: bytes) -> dict[str, Any]:
    messages = [
        {**m, "data": base64.b64encode(stream).decode()} if m["topic"] == topic else m
        for m in bundle["messages"]
    ]
    return {**bundle, "messages": messages}


def test_deflated_data_has_one_spelling(proved: tuple[Path, Path], keys: Keys) -> None:
    """The same bytes deflated otherwise still verify (the digests cover the bytes), but a
    stream with its padding bits set, a zlib header, trailing bytes or a bomb is refused."""
    _root, bundle = proved
    data = json.loads(bundle.read_text())
    key, witness = load_public_key(keys.robot_pub), keys.witness_verifier
    [action] = [m for m in data["messages"] if m["topic"] == "/trace/action"]
    stream = base64.b64decode(action["data"])
    raw = zlib.decompress(stream, -15)

    fast = zlib.compressobj(1, zlib.DEFLATED, -15)
    other = fast.compress(raw) + fast.flush()
    assert other != stream
    assert check_bundle(_rewrap(data, "/trace/action", other), key, witness_key=witness).ok

    def inflates_whole(candidate: bytes) -> bool:
        inflate = zlib.decompressobj(-15)
        try:
            out = inflate.decompress(candidate)
        except zlib.error:
            return False
        return out == raw and inflate.eof and not inflate.unused_data

    flipped = (stream[:-1] + bytes([stream[-1] | 1 << bit]) for bit in range(8))
    padded = [bad for bad in flipped if bad != stream and inflates_whole(bad)]
    assert padded  # the final byte of this deflate stream has unused bits
    for bad in padded:
        checked = check_bundle(_rewrap(data, "/trace/action", bad), key, witness_key=witness)
        assert not checked.ok and "padding bits" in checked.steps[-1][2]

    with_header = zlib.compress(raw)
    bomb_maker = zlib.compressobj(9, zlib.DEFLATED, -15)
    bomb = bomb_maker.compress(bytes(80 << 20)) + bomb_maker.flush()
    for bad in (with_header, stream + b"\0", stream[:-3], bomb):
        checked = check_bundle(_rewrap(data, "/trace/action", bad), key, witness_key=witness)
        assert not checked.ok and "raw DEFLATE" in checked.steps[-1][2]


def test_a_segment_file_proves_as_its_root_does(proved: tuple[Path, Path], keys: Keys) -> None:
    """``prove`` takes "a log root or segment" (its help): a segment file has no witness
    store beside it, so its bundle names the robot's own newest checkpoint."""
    root, bundle = proved
    [segment] = sorted((root / "hot").glob("*.mcap"))[:1]
    alone = bundle.parent / "alone.json"
    made = run_cli("prove", str(segment), "--cycle", "37", "--out", str(alone))
    assert made.returncode == 0, made.stderr
    data = json.loads(alone.read_text())
    assert data["cycle"] == 37 and not data["cosigned"]
    checked = run_cli("verify-proof", str(alone), "--key", str(keys.robot_pub))
    assert checked.returncode == 0, checked.stdout + checked.stderr


def test_prove_never_overwrites_and_names_the_file_it_could_not_write(
    proved: tuple[Path, Path],
) -> None:
    root, bundle = proved
    before = bundle.read_bytes()
    again = run_cli("prove", str(root), "--cycle", "38", "--out", str(bundle))
    assert again.returncode == 4 and bundle.read_bytes() == before
    assert again.stderr.count("\n") == 1 and "never overwritten" in again.stderr
    nowhere = bundle.parent / "no-such-folder" / "x.json"
    missing = run_cli("prove", str(root), "--cycle", "38", "--out", str(nowhere))
    assert missing.returncode == 4 and missing.stderr.count("\n") == 1
    assert f"{nowhere}: cannot write" in missing.stderr and ".partial" not in missing.stderr
    assert not list(bundle.parent.glob(".*.partial"))


def test_a_bundle_that_fails_before_its_tree_says_so(proved: tuple[Path, Path], keys: Keys) -> None:
    _root, bundle = proved
    data = json.loads(bundle.read_text())
    first = data["messages"][0]
    data["messages"][0] = {**first, "data": "A" + first["data"][1:]}
    broken = bundle.parent / "broken.json"
    broken.write_text(json.dumps(data))
    done = run_cli("verify-proof", str(broken), "--key", str(keys.robot_pub), "--plain")
    assert done.returncode == 1
    assert "tree   not reached" in done.stdout and "None" not in done.stdout


def test_prove_on_a_log_whose_checkpoints_are_unsigned_says_so(tmp_path: Path) -> None:
    """Found from outside: an unsigned log was told that "a later checkpoint is needed"."""
    with AuditLogger(tmp_path / "log", robot_id="r", period_s=0.1) as logger:
        for i in range(30):
            p, b, a, e = synthetic_cycle(i)
            logger.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    done = cli("prove", tmp_path / "log", "--cycle", "3", "--out", tmp_path / "p.json")
    one_line(done, 2, "checkpoints are not signed", "checkpoint key")
