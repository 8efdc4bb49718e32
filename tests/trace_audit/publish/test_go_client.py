"""The issue's bar: an outside Go program using only x/mod's ``note`` and ``tlog`` fetches a
published robot's tree over HTTP from a static server, verifies its checkpoint, recomputes
the root from the tiles, proves the inclusion of the seal ``trace-audit prove`` names and the
consistency of the trees published before and after the robot logged more; a changed byte
anywhere it reads makes it fail."""

from __future__ import annotations

import base64
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.outside import cli
from tests.trace_audit.publish.conftest import ORIGIN, GoClient, RobotKey
from tests.trace_audit.witness.test_tail import write
from trace_runtime.tlog.tlog_proof import parse_tlog_proof


def publish(root: Path, out: Path) -> dict[str, Any]:
    done = cli("publish", root, "--out", out, "--json")
    assert done.returncode == 0, done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return report


def prove(root: Path, cycle: int, tmp_path: Path) -> dict[str, Any]:
    bundle = tmp_path / f"cycle-{cycle}.json"
    made = cli("prove", root, "--cycle", cycle, "--out", bundle)
    assert made.returncode == 0, made.stderr
    data: dict[str, Any] = json.loads(bundle.read_text())
    return data


@pytest.fixture
def published(tmp_path: Path, robot_key: RobotKey) -> tuple[Path, Path]:
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, robot_key.private, range(600))  # two full tiles and a partial one
    publish(root, out)
    return root, out


def test_go_verifies_the_published_tree_and_proves_a_seal(
    published: tuple[Path, Path],
    tmp_path: Path,
    robot_key: RobotKey,
    go_client: GoClient,
    static_server: Callable[[Path], str],
) -> None:
    root, out = published
    url = static_server(out) + "/amr-7"
    bundle = prove(root, 300, tmp_path)
    request = {"url": url, "vkey": robot_key.vkey, "index": bundle["leaf_index"],
               "proof": bundle["tlog_proof"]}  # fmt: skip
    done = go_client(request)
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    assert (answer["origin"], answer["size"]) == (ORIGIN, 600)
    assert base64.b64decode(answer["entry"]) == base64.b64decode(bundle["seal"])
    assert bundle["tree_size"] == 600  # the same tree: Go's proof is the bundle's
    hashes = parse_tlog_proof(bundle["tlog_proof"]).hashes
    assert [base64.b64decode(h) for h in answer["inclusion"]] == list(hashes)
    assert (answer["proof_index"], answer["proof_size"]) == (bundle["leaf_index"], 600)
    i = bundle["leaf_index"]
    moved = bundle["tlog_proof"].replace(f"index {i}\n", f"index {i + 1}\n")
    refused = go_client({**request, "proof": moved})  # the bundle's proof, of another leaf
    assert refused.returncode == 1 and "tlog-proof" in refused.stderr, refused.stderr
    assert any("/tile/0/001" in u for u in answer["fetched"])
    assert any("/tile/entries/001" in u for u in answer["fetched"])

    old_note = (out / "amr-7" / "checkpoint").read_text()
    write(root, robot_key.private, range(600, 1100))
    again = publish(root, out)["robots"][0]
    assert (again["previous_size"], again["tree_size"]) == (600, 1100)
    assert again["kept"] > 0
    request = {"url": url, "vkey": robot_key.vkey, "index": bundle["leaf_index"],
               "old_note": old_note}  # fmt: skip
    later = go_client(request)
    assert later.returncode == 0, later.stderr
    answer = json.loads(later.stdout)
    assert (answer["old_size"], answer["size"]) == (600, 1100)
    assert answer["consistency"]
    assert base64.b64decode(answer["entry"]) == base64.b64decode(bundle["seal"])


# tlog refuses a tile that does not hash to its parent ("inconsistent tile") or, for a
# tile it authenticates through the proof itself, the proof ("invalid transparency proof")
TILE = ("inconsistent tile", "invalid transparency proof")
CHANGED = [  # a file, a leaf whose proof reads it, and what the Go client may say
    ("tile/0/000", 100, TILE),  # a full hash tile
    ("tile/0/001", 300, TILE),
    ("tile/0/002.p/88", 300, TILE),  # the partial tile of the checkpoint's size
    ("tile/1/000.p/2", 300, TILE),  # the level above
    ("tile/entries/001", 300, ("check record",)),  # the entry bundle holding leaf 300
    ("checkpoint", 300, ("checkpoint",)),  # a byte of the signed note's root
]


@pytest.mark.parametrize(("name", "index", "says"), CHANGED)
def test_a_changed_byte_fails_the_go_client(
    published: tuple[Path, Path],
    robot_key: RobotKey,
    *,
    go_client: GoClient,
    static_server: Callable[[Path], str],
    name: str,
    index: int,
    says: tuple[str, ...],
) -> None:
    _root, out = published
    url = static_server(out) + "/amr-7"
    request = {"url": url, "vkey": robot_key.vkey, "index": index}
    before = go_client(request)
    assert before.returncode == 0, before.stderr
    assert f"{url}/{name}" in json.loads(before.stdout)["fetched"]
    path = out / "amr-7" / name
    data = bytearray(path.read_bytes())
    if name == "checkpoint":
        at = data.index(b"\n") + 5  # the root's first base64 digit
    elif "entries" in name:
        at = data.index(f'"cycle":{index},'.encode()) + 9  # in the seal proved, not another
    else:
        at = len(data) // 2 + 7
    data[at] ^= 0x01
    path.write_bytes(bytes(data))
    done = go_client(request)
    assert done.returncode == 1, done.stdout
    assert any(s in done.stderr for s in says), done.stderr
