"""Proof bundles: one cycle of a real logger root, proved to a signed and cosigned checkpoint
and checked without the log; every byte of the bundle changed makes it fail."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import orjson
import pytest

from tests.trace_audit.witness.conftest import Keys, WitnessProcess, run_cli
from tests.trace_audit.witness.test_tail import write
from trace_audit.proof import BUNDLE_FORMAT, check_bundle
from trace_runtime.keys import load_public_key


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


def test_a_bundle_of_the_first_format_still_verifies(proved: tuple[Path, Path], keys: Keys) -> None:
    """``trace-proof/1`` (before the readings were carried) is checked as before; its
    readings are simply not there to check."""
    _root, bundle = proved
    data = json.loads(bundle.read_text())
    key, witness = load_public_key(keys.robot_pub), keys.witness_verifier
    old = {k: v for k, v in data.items() if k != "sensors"} | {"format": "trace-proof/1"}
    checked = check_bundle(old, key, witness_key=witness)
    assert checked.ok and "sensors" not in [name for name, _ok, _detail in checked.steps]
    mixed = {**data, "format": "trace-proof/1"}  # a /1 bundle with a field /1 does not have
    assert not check_bundle(mixed, key, witness_key=witness).ok
    quiet = {**data, "sensors": []}  # the reading left out: the seal counts one
    assert not check_bundle(quiet, key, witness_key=witness).ok
