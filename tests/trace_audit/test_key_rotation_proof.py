"""Proof bundles after a key rotation (``trace-proof/5``'s ``key_rotations``): a decision of
a robot that rotated its key is proved to a checkpoint the new key signed, and the bundle
carries the announcements that lead there, so ``verify-proof --key OLD`` (the key an auditor
was given first) verifies it without the log; the new key verifies it too, saying what it
could not check; any other key, a forged announcement, or any byte of the announcements
changed fails."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.outside import cli
from tests.trace_audit.test_key_rotation import serving, write
from trace_audit.proof import BUNDLE_FORMAT, check_bundle
from trace_runtime.tlog.keys import KeyPair, generate_keypair, load_public_key, load_signer
from trace_runtime.tlog.signed_note import COSIGNATURE, verifier_key


@pytest.fixture(scope="module")
def pairs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, KeyPair]:
    folder = tmp_path_factory.mktemp("keys")
    return {n: generate_keypair(folder, name=n) for n in ("old", "new", "evil")}


@pytest.fixture(scope="module")
def bundles(tmp_path_factory: pytest.TempPathFactory, pairs: dict[str, KeyPair]) -> Path:
    """Bundles of cycles 30 (before the rotation at 62) and 100 (after), proved to the
    newest checkpoint (the new key's); the log is removed: the bundles stand alone."""
    base = tmp_path_factory.mktemp("rotated")
    root = base / "root"
    write(root, pairs["old"].private_path, range(120), rotate={62: pairs["new"].private_path})
    write(root, pairs["new"].private_path, range(120, 160))
    for cycle in (30, 100):
        made = cli("prove", root, "--cycle", str(cycle), "--out", base / f"cycle-{cycle}.json")
        assert made.returncode == 0, made.stderr
    shutil.rmtree(root)
    return base


def verify_proof(bundle: Path, key: Path) -> tuple[int, dict[str, Any]]:
    done = cli("verify-proof", bundle, "--key", key, "--json")
    assert done.returncode in (0, 1), done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return done.returncode, report


def steps(report: dict[str, Any]) -> dict[str, tuple[bool, str]]:
    return {s[0]: (s[1], s[2]) for s in report["steps"]}


def test_the_first_key_verifies_a_decision_after_the_rotation(
    bundles: Path, pairs: dict[str, KeyPair]
) -> None:
    for cycle in (30, 100):
        bundle = bundles / f"cycle-{cycle}.json"
        data = json.loads(bundle.read_text())
        assert data["format"] == BUNDLE_FORMAT
        [rotation] = data["key_rotations"]
        new_raw = load_signer(pairs["new"].private_path).public_key.raw
        assert rotation["key_id"] == pairs["old"].key_id
        assert rotation["next_key"] == verifier_key("trace.local/amr-7", new_raw)
        code, report = verify_proof(bundle, pairs["old"].public_path)
        assert code == 0, report["steps"]
        assert steps(report)["keys"] == (True, "followed 1 key rotation(s) from the key given")


def test_the_new_key_verifies_it_and_says_what_it_did_not_check(
    bundles: Path, pairs: dict[str, KeyPair]
) -> None:
    code, report = verify_proof(bundles / "cycle-100.json", pairs["new"].public_path)
    assert code == 0, report["steps"]
    ok, detail = steps(report)["keys"]
    assert ok and "1 before it not checked" in detail


def test_a_key_outside_the_rotations_fails(bundles: Path, pairs: dict[str, KeyPair]) -> None:
    code, report = verify_proof(bundles / "cycle-100.json", pairs["evil"].public_path)
    assert code == 1
    assert steps(report)["keys"][0] is False


def test_a_forged_announcement_fails(
    bundles: Path, pairs: dict[str, KeyPair], tmp_path: Path
) -> None:
    """The announcement rewritten to hand the chain to the attacker's key (who holds the
    new key's role but never had the old key): its signature no longer verifies."""
    data = json.loads((bundles / "cycle-100.json").read_text())
    evil_raw = load_signer(pairs["evil"].private_path).public_key.raw
    data["key_rotations"][0]["next_key"] = verifier_key("trace.local/amr-7", evil_raw)
    forged = tmp_path / "forged.json"
    forged.write_text(json.dumps(data))
    code, report = verify_proof(forged, pairs["old"].public_path)
    assert code == 1
    cycle = data["key_rotations"][0]["cycle"]  # the checkpoint after the rotation at 62
    assert steps(report)["keys"] == (
        False,
        f"the key rotation at cycle {cycle} does not verify under its key",
    )


def test_every_byte_of_the_rotations_changed_fails(
    bundles: Path, pairs: dict[str, KeyPair]
) -> None:
    original = (bundles / "cycle-100.json").read_bytes()
    key = load_public_key(pairs["old"].public_path)
    start = original.index(b'"key_rotations"')
    end = original.index(b"]", start) + 1
    assert check_bundle(orjson.loads(original), key).ok
    passed = []
    for i in range(start, end):
        for flip in (0x01, 0x20):
            changed = bytearray(original)
            changed[i] ^= flip
            try:
                value = orjson.loads(bytes(changed))
            except orjson.JSONDecodeError:
                continue
            if isinstance(value, dict) and check_bundle(value, key).ok:
                passed.append((i, flip, original[max(0, i - 20) : i + 20]))
    assert not passed, passed[:5]


def test_a_key_never_announced_carries_no_rotation_and_fails(
    tmp_path: Path, pairs: dict[str, KeyPair]
) -> None:
    root = tmp_path / "root"
    write(root, pairs["old"].private_path, range(60))
    write(root, pairs["evil"].private_path, range(60, 110))  # root, no old key: a fresh key
    bundle = tmp_path / "cycle-30.json"
    assert cli("prove", root, "--cycle", "30", "--out", bundle).returncode == 0
    assert json.loads(bundle.read_text())["key_rotations"] == []
    code, report = verify_proof(bundle, pairs["old"].public_path)
    assert code == 1 and steps(report)["note"][0] is False


def test_cosigned_bundles_carry_the_rotations_before_their_note(
    tmp_path: Path, pairs: dict[str, KeyPair]
) -> None:
    """A witness given both keys cosigns the robot's notes before and after the rotation;
    each bundle is proved to the smallest cosigned tree covering its cycle, and carries the
    rotations before that note only: none for the announcing checkpoint's own note (the old
    key signed it), one after it. Each verifies with the first key and the witness's key."""
    origin, name = "trace.local/amr-7", "trace.local/witness"
    witness = generate_keypair(tmp_path / "witness", name="witness")
    w_vkey = verifier_key(name, load_signer(witness.private_path).public_key.raw, COSIGNATURE)
    vkeys = [verifier_key(origin, load_signer(pairs[n].private_path).public_key.raw)
             for n in ("old", "new")]  # fmt: skip
    root = tmp_path / "root"
    with serving(tmp_path / "state", witness.private_path, *vkeys) as url:
        failures = write(root, pairs["old"].private_path, range(60),
                         rotate={30: pairs["new"].private_path}, witness=url)  # fmt: skip
        failures += write(root, pairs["new"].private_path, range(60, 100), witness=url)
    assert failures == 0

    def proved(cycle: int) -> tuple[Path, dict[str, Any]]:
        bundle = tmp_path / f"cycle-{cycle}.json"
        made = cli("prove", root, "--cycle", str(cycle), "--out", bundle)
        assert made.returncode == 0, made.stderr
        data: dict[str, Any] = json.loads(bundle.read_text())
        assert data["cosigned"], data["tree_size"]
        return bundle, data

    after, data = proved(80)
    [rotation] = data["key_rotations"]
    announcing, own = proved(rotation["cycle"])  # its tree: the announcing checkpoint's
    assert own["tree_size"] == rotation["cycle"] + 1 and own["key_rotations"] == []
    for bundle in (after, announcing):
        done = cli("verify-proof", bundle, "--key", pairs["old"].public_path,
                   "--witness-key", w_vkey, "--json")  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        assert "cosignature" in steps(json.loads(done.stdout))
