"""``trace-audit mcp --key PUB [--witness-key VKEY]`` from the outside, through the MCP SDK's
own client over stdio: with the robot's key, "verified" includes the checkpoints' signatures
(key rotations followed, as ``verify --key``) and, with the witness's key, what a real
witness cosigned (``witness push`` into the log root's store); a log signed by another key is
integrity failed (``key_mismatch``), a witness key that did not cosign is integrity failed
too; without a key the answer says signatures were not checked."""

from __future__ import annotations

import json
import shlex
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.assistant.test_server import _serve
from tests.trace_audit.test_key_rotation import write as write_rotating
from tests.trace_audit.witness.conftest import (
    WITNESS_NAME,
    Keys,
    WitnessProcess,
    keys,
    run_cli,
    witness_process,
)
from tests.trace_audit.witness.test_tail import write
from trace_runtime.tlog.keys import generate_keypair, load_public_key
from trace_runtime.tlog.signed_note import COSIGNATURE, verifier_key

pytest.importorskip("mcp")

from mcp import ClientSession

__all__ = ["keys", "witness_process"]  # the witness tests' fixtures, used here too


@pytest.fixture
def root(tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]) -> Path:
    """A root holding a signed log pushed to a real witness (witnessed/: its root's store
    holds the cosigned checkpoints) and a log rotated from the robot's key to another
    (rotated/: announced in its chain, no witness)."""
    root = tmp_path / "root"
    write(root / "witnessed", keys.robot_key, range(120))
    w = witness_process()
    pushed = run_cli("witness", "push", str(root / "witnessed"), "--witness", w.url, "--json")
    assert pushed.returncode == 0, pushed.stdout + pushed.stderr
    new = generate_keypair(tmp_path / "new", name="new").private_path
    write_rotating(root / "rotated", keys.robot_key, range(80), rotate={40: new})
    return root


def integrity(serve_args: list[str], root: Path, *logs: str) -> list[dict[str, Any]]:
    """Each log's verify answer (its structured content) from one server process; another
    tool's answer on the log (timeline) carries the same integrity, from the same verify."""

    async def ask(s: ClientSession) -> list[dict[str, Any]]:
        answers = []
        for log in logs:
            result = await s.call_tool("verify", {"log": log})
            other = await s.call_tool("timeline", {"log": log})
            assert result.structured_content is not None, result
            assert other.structured_content is not None, other
            seen = result.structured_content["integrity"], other.structured_content["integrity"]
            assert seen[1]["scope"]["cached"], seen  # the verify answer's report, kept
            assert seen[0] | {"scope": None} == seen[1] | {"scope": None}
            answers.append(result.structured_content)
        return answers

    return _serve([root], ask, *serve_args)


def test_with_the_robots_and_the_witnesss_keys_verified_includes_both(
    root: Path, keys: Keys
) -> None:
    args = ["--key", str(keys.robot_pub), "--witness-key", keys.witness_verifier.vkey]
    witnessed, rotated = integrity(args, root, "witnessed", "rotated")
    status = witnessed["integrity"]
    assert status["status"] == "verified", status
    scope = status["scope"]
    assert (scope["signatures_checked"], scope["witness_checked"]) == (True, True)
    assert scope["witnessed"] >= 1
    assert "signed by the robot's key" in status["summary"]
    assert "cosigned by the witness agree with the log" in status["summary"]
    # The answer is the command's: the reproduce line prints the same verify, keys and all.
    words = shlex.split(witnessed["reproduce"])
    assert words[words.index("--key") + 1] == str(keys.robot_pub.resolve())
    assert words[words.index("--witness") + 1] == "local"
    done = cli(*words[1:])
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["witness"] == witnessed["data"]["witness"]
    # A rotated robot: the first key is enough; no witness cosigned it, and that is said.
    status = rotated["integrity"]
    assert status["status"] == "verified", status
    assert status["scope"]["signatures_checked"] and status["scope"]["witnessed"] == 0
    assert "no checkpoint of theirs is cosigned" in status["summary"]
    assert len(rotated["data"]["robots"][0]["announced_keys"]) == 1


def test_without_a_key_the_answer_says_signatures_were_not_checked(root: Path) -> None:
    [answer] = integrity([], root, "witnessed")
    status = answer["integrity"]
    assert status["status"] == "verified"
    assert (status["scope"]["signatures_checked"], status["scope"]["witness_checked"]) == (
        False,
        False,
    )
    assert "signatures not checked" in status["summary"]
    assert "--key" not in answer["reproduce"]


def test_a_log_signed_by_another_key_is_integrity_failed(root: Path, tmp_path: Path) -> None:
    stranger = generate_keypair(tmp_path / "stranger", name="other").public_path
    [answer] = integrity(["--key", str(stranger)], root, "witnessed")
    status = answer["integrity"]
    assert status["status"] == "integrity_failed"
    assert status["summary"].startswith("integrity failed")
    assert {f["kind"] for f in status["findings"]} == {"key_mismatch"}


def test_a_witness_key_that_did_not_cosign_is_integrity_failed(
    root: Path, keys: Keys, tmp_path: Path
) -> None:
    other = generate_keypair(tmp_path / "other", name="w2").public_path
    vkey = verifier_key(WITNESS_NAME, load_public_key(other).raw, COSIGNATURE)
    [answer] = integrity(["--key", str(keys.robot_pub), "--witness-key", vkey], root, "witnessed")
    status = answer["integrity"]
    assert status["status"] == "integrity_failed", status
    assert "bad_signature" in {f["kind"] for f in status["findings"]}


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--witness-key", "not a key"], "--witness-key"),
        (["--key", "/nonexistent/amr-7.pub"], "amr-7.pub"),
    ],
)
def test_a_bad_key_is_one_line_and_exit_2(tmp_path: Path, args: list[str], needle: str) -> None:
    one_line(cli("mcp", "--root", tmp_path, *args), 2, needle)
