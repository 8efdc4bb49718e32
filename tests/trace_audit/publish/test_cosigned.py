"""The cosigned checkpoint served: after ``witness push`` (a real ``witness serve`` process)
the root's witness store holds the published size cosigned, and ``publish`` serves that note,
so the outside Go client opens it with x/mod's ``note.Open`` under both the robot's and the
witness's verifier keys; a store line that is not the same note plus well-formed lines is
left out, never served."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson
import pytest

from tests.outside import cli
from tests.trace_audit.publish.conftest import GoClient
from tests.trace_audit.witness.conftest import (
    ORIGIN,
    WITNESS_NAME,
    Keys,
    WitnessProcess,
    keys,
    run_cli,
    witness_process,
)
from tests.trace_audit.witness.test_tail import write
from trace_runtime.tlog.cosignature_store import store_path

__all__ = ["keys", "witness_process"]  # the witness tests' fixtures, used here too


def publish(root: Path, out: Path, *args: str | Path) -> dict[str, Any]:
    done = cli("publish", root, "--out", out, "--json", *args)
    assert done.returncode == 0, done.stderr
    report: dict[str, Any] = json.loads(done.stdout)["robots"][0]
    return report


@pytest.fixture
def root(tmp_path: Path, keys: Keys) -> Path:
    root = tmp_path / "root"
    write(root, keys.robot_key, range(300))
    return root


def push(root: Path, w: WitnessProcess) -> None:
    done = run_cli("witness", "push", str(root), "--witness", w.url, "--json")
    assert done.returncode == 0, done.stdout + done.stderr
    assert json.loads(done.stdout)["robots"][0]["witness_size"] == 300


def test_go_opens_the_served_note_under_the_robots_and_the_witnesss_keys(
    root: Path,
    tmp_path: Path,
    *,
    keys: Keys,
    witness_process: Callable[..., WitnessProcess],
    go_client: GoClient,
    static_server: Callable[[Path], str],
) -> None:
    out = tmp_path / "out"
    before = publish(root, out, "--key", keys.robot_pub)
    assert before["cosigned_by"] == []
    url = static_server(out) + "/amr-7"
    request = {"url": url, "vkey": keys.robot_vkey, "index": 150,
               "witness_vkey": keys.witness_verifier.vkey}  # fmt: skip
    refused = go_client(request)  # not cosigned yet: a client that requires it refuses
    assert refused.returncode == 1 and "no cosignature by" in refused.stderr, refused.stderr
    robot_note = (out / "amr-7" / "checkpoint").read_text()

    push(root, witness_process())
    after = publish(root, out, "--key", keys.robot_pub)
    assert after["cosigned_by"] == [WITNESS_NAME]
    assert (after["previous_size"], after["tree_size"]) == (300, 300)
    served = (out / "amr-7" / "checkpoint").read_text()
    assert served.startswith(robot_note) and served.count("\n\u2014 ") == 2
    done = go_client(request)
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    assert sorted(answer["signers"]) == sorted([ORIGIN, WITNESS_NAME])
    assert answer["cosigned_at"] > 1_700_000_000 and answer["size"] == 300
    assert go_client({**request, "witness_vkey": ""}).returncode == 0  # the robot's key alone
    stranger = keys.witness_verifier.vkey.replace(WITNESS_NAME, "trace.local/other")
    other = go_client({**request, "witness_vkey": stranger})
    assert other.returncode == 1, other.stdout  # another witness's key: its hash differs


def test_store_lines_that_are_not_the_robots_note_cosigned_are_not_served(
    root: Path, tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]
) -> None:
    push(root, witness_process())
    store = store_path(root, "amr-7")
    lines = store.read_bytes().splitlines()
    newest = orjson.loads(lines[-1])
    assert newest["tree_size"] == 300
    body, _, signatures = newest["note"].partition("\n\n")
    robot_line, cosignature = signatures.splitlines()[:2]
    damaged = [
        {**newest, "note": newest["note"][:-6] + "!!!!=\n"},  # not base64
        {**newest, "note": body.replace("300", "301", 1) + "\n\n" + signatures},  # another text
        {**newest, "note": f"{body}\n\n{robot_line[:-4]}AAA=\n{cosignature}\n"},  # robot sig
    ]
    kept = [line for line in lines if orjson.loads(line)["tree_size"] != 300]
    store.write_bytes(b"".join(line + b"\n" for line in kept + [orjson.dumps(d) for d in damaged]))
    report = publish(root, tmp_path / "out")
    assert report["cosigned_by"] == []
    served = (tmp_path / "out" / "amr-7" / "checkpoint").read_text()
    assert served.count("\u2014 ") == 1 and cosignature not in served
