"""``publish --key OLD`` after a key rotation (profile 1.5): publish follows the keys the
robot's chain announced from the key given, as ``verify --key OLD`` does, so the robot's
first key is enough to publish a log whose newest note the announced key signed; the
announced key (``announced_keys``, as verify's) is what the outside Go client opens the
served note with. A newest note under a key never announced, or under a key already rotated
away from, publishes nothing (exit 1)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tests.outside import cli
from tests.trace_audit.publish.conftest import ORIGIN, GoClient
from tests.trace_audit.test_key_rotation import write
from trace_runtime.tlog.keys import KeyPair, generate_keypair, load_signer
from trace_runtime.tlog.signed_note import verifier_key


def publish(root: Path, out: Path, *args: str | Path) -> tuple[int, dict[str, Any]]:
    done = cli("publish", root, "--out", out, "--json", *args)
    assert done.returncode in (0, 1), done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return done.returncode, report


def pairs(tmp_path: Path) -> dict[str, KeyPair]:
    return {n: generate_keypair(tmp_path / "keys", name=n) for n in ("old", "new", "evil")}


def vkey(pair: KeyPair) -> str:
    return verifier_key(ORIGIN, load_signer(pair.private_path).public_key.raw)


def test_the_first_key_publishes_a_rotated_robot(
    tmp_path: Path, go_client: GoClient, static_server: Callable[[Path], str]
) -> None:
    keys = pairs(tmp_path)
    old, new = keys["old"], keys["new"]
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, old.private_path, range(120), rotate={62: new.private_path})
    write(root, new.private_path, range(120, 160))  # a restart signs with the announced key
    code, report = publish(root, out, "--key", old.public_path)
    assert code == 0, report
    [robot] = report["robots"]
    assert (robot["problems"], robot["tree_size"]) == ([], 160)
    assert robot["announced_keys"] == [vkey(new)]
    assert report["key_ids"] == [old.key_id]
    # The outside client opens the served note with the key the chain announced.
    request = {"url": static_server(out) + "/amr-7", "vkey": robot["announced_keys"][-1],
               "index": 100}  # fmt: skip
    done = go_client(request)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["size"] == 160
    refused = go_client({**request, "vkey": vkey(old)})  # the old key did not sign it
    assert refused.returncode == 1, refused.stdout
    # The new key alone still publishes it (the note is its), and so do both keys.
    assert publish(root, tmp_path / "new", "--key", new.public_path)[0] == 0
    code, both = publish(
        root, tmp_path / "both", "--key", new.public_path, "--key", old.public_path
    )
    assert code == 0 and both["robots"][0]["announced_keys"] in ([], [vkey(new)])


def test_a_key_never_announced_publishes_nothing(tmp_path: Path) -> None:
    keys = pairs(tmp_path)
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, keys["old"].private_path, range(60))
    # Root on the robot without the old key: the log goes on under a fresh key.
    write(root, keys["evil"].private_path, range(60, 110))
    code, report = publish(root, out, "--key", keys["old"].public_path)
    assert code == 1
    [robot] = report["robots"]
    [problem] = robot["problems"]
    assert "not signed by the key given" in problem and "nothing published" in problem
    assert robot["tree_size"] is None and robot["announced_keys"] == []
    assert not (out / "amr-7").exists()


def test_a_key_rotated_away_from_publishes_nothing(tmp_path: Path) -> None:
    keys = pairs(tmp_path)
    old, new = keys["old"], keys["new"]
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, old.private_path, range(60), rotate={30: new.private_path})
    # The old key (maybe the stolen one, the reason for the rotation) signs again later.
    write(root, old.private_path, range(60, 100))
    for given in ([old.public_path], [old.public_path, "--key", new.public_path]):
        code, report = publish(root, out, "--key", *given)
        assert code == 1
        [problem] = report["robots"][0]["problems"]
        assert "retired by the rotation at cycle" in problem, problem
        assert not (out / "amr-7").exists()
