"""``trace-audit witness serve`` as a real process: C2SP tlog-witness add-checkpoint rules
(200 with a cosignature, 409 with its size, 403, 404, 422, 400), GET /checkpoint/<origin>,
its state kept across a restart, and SIGTERM ending it with exit 0."""

from __future__ import annotations

import hashlib
import urllib.parse
import urllib.request
from collections.abc import Callable

from tests.trace_audit.witness.conftest import ORIGIN, Keys, WitnessProcess, run_cli
from trace_runtime.tlog.keys import Ed25519Signer
from trace_runtime.tlog.merkle import consistency_proof, root_of
from trace_runtime.tlog.signed_note import (
    NoteSigner,
    format_checkpoint,
    open_note,
    sign_note,
    verify_cosignature,
)
from trace_runtime.tlog.witness_client import Submitted, submit

LEAVES = [hashlib.sha256(b"leaf %d" % i).digest() for i in range(40)]
OTHER = [hashlib.sha256(b"other %d" % i).digest() for i in range(40)]


def _note(signer: NoteSigner, leaves: list[bytes], size: int, origin: str = ORIGIN) -> str:
    return sign_note(format_checkpoint(origin, size, root_of(leaves[:size])), signer)


def _send(
    url: str, signer: NoteSigner, old: int, size: int, *, leaves: list[bytes] = LEAVES
) -> Submitted:
    proof = consistency_proof(old, leaves[:size])
    return submit(url, old, proof, _note(signer, leaves, size), timeout_s=10)


def test_add_checkpoint_rules(keys: Keys, witness_process: Callable[..., WitnessProcess]) -> None:
    w = witness_process()
    robot = keys.robot_signer
    first = _send(w.url, robot, 0, 4)
    assert first.ok, first
    body = format_checkpoint(ORIGIN, 4, root_of(LEAVES[:4]))
    stamp = verify_cosignature(body, first.cosignatures[0], keys.witness_verifier)
    assert stamp > 1_700_000_000
    later = _send(w.url, robot, 4, 17)
    assert later.ok, later
    # the client's old size is not the witness's: 409 with its size
    stale = _send(w.url, robot, 4, 20)
    assert (stale.outcome, stale.status, stale.witness_size) == ("conflict", 409, 17)
    # an older tree, with the old size it knew: 409 too
    older = _send(w.url, robot, 4, 10)
    assert (older.status, older.witness_size) == (409, 17)
    # same size, another root
    fork = _send(w.url, robot, 17, 17, leaves=OTHER)
    assert (fork.status, fork.witness_size) == (409, 17)
    # a larger tree that does not extend the witnessed one: its proof cannot verify
    rewritten = _send(w.url, robot, 17, 30, leaves=OTHER)
    assert rewritten.status == 422, rewritten
    # a proof from the wrong size
    lying = submit(w.url, 17, consistency_proof(16, LEAVES[:30]), _note(robot, LEAVES, 30))
    assert lying.status == 422
    # a note signed by another key under the robot's origin
    stranger = Ed25519Signer.generate()
    forged = _send(w.url, NoteSigner(ORIGIN, stranger, stranger.public_key.raw), 17, 30)
    assert forged.status == 403, forged
    # an origin the witness was not given
    unknown = submit(w.url, 0, [], _note(robot, LEAVES, 3, origin="trace.local/amr-9"))
    assert unknown.status == 404
    # malformed
    garbage = urllib.request.Request(w.url + "/add-checkpoint", data=b"old x\n\n", method="POST")
    try:
        urllib.request.urlopen(garbage, timeout=10)
        raise AssertionError("a malformed request was accepted")
    except urllib.error.HTTPError as err:
        assert err.code == 400
        err.close()
    # the witness moved on only with the consistent checkpoint
    assert _send(w.url, robot, 17, 40).ok
    with urllib.request.urlopen(
        w.url + "/checkpoint/" + urllib.parse.quote(ORIGIN, safe="/"), timeout=10
    ) as response:
        note = response.read().decode()
    opened = open_note(note, [robot.verifier, keys.witness_verifier])
    assert opened.text == format_checkpoint(ORIGIN, 40, root_of(LEAVES))
    assert len(opened.verified) == 2


def test_state_survives_a_restart(
    keys: Keys, witness_process: Callable[..., WitnessProcess]
) -> None:
    w = witness_process()
    robot = keys.robot_signer
    assert _send(w.url, robot, 0, 9).ok
    w.restart()
    again = _send(w.url, robot, 0, 12)
    assert (again.status, again.witness_size) == (409, 9)
    assert _send(w.url, robot, 9, 12).ok
    w.restart()
    assert _send(w.url, robot, 12, 12, leaves=OTHER).status == 409
    assert w.exit_codes == [0, 0]


def test_usage(keys: Keys) -> None:
    vkey = run_cli("witness", "vkey", "--key", str(keys.robot_pub), "--origin", ORIGIN)
    assert vkey.returncode == 0 and vkey.stdout.strip() == keys.robot_vkey
    assert run_cli("witness", "serve", "--key", str(keys.witness_key)).returncode == 2
    bad = run_cli("witness", "serve", "--state", "/tmp/x", "--key", str(keys.witness_key),
                  "--log", "not-a-vkey")  # fmt: skip
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert run_cli("witness", "dance").returncode == 2
