"""``witness serve --tiles DIR``: one real process is the robot's witness and serves its
published tree; the outside Go client reads the tree from it and requires the witness's
cosignature on the note. Only the names of a published tree are served, never a file outside
DIR or through a link, a FIFO, or a name off the tiles grammar."""

from __future__ import annotations

import http.client
import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.outside import REPO, cli, one_line
from tests.trace_audit.publish.conftest import GoClient
from tests.trace_audit.witness.conftest import WITNESS_NAME, Keys, keys, run_cli
from tests.trace_audit.witness.test_tail import write

__all__ = ["keys"]  # the witness tests' fixture, used here too


def serve(keys: Keys, state: Path, tiles: Path) -> tuple[subprocess.Popen[str], str]:
    args = [sys.executable, "-m", "trace_audit.cli", "witness", "serve", "--listen",
            "127.0.0.1:0", "--state", str(state), "--key", str(keys.witness_key), "--name",
            WITNESS_NAME, "--log", keys.robot_vkey, "--tiles", str(tiles)]  # fmt: skip
    process = subprocess.Popen(
        args,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert process.stderr is not None
    line = process.stderr.readline()
    assert "listening on " in line and "serving the tiles of" in line, line
    return process, line.split("listening on ", 1)[1].split()[0]


@pytest.fixture
def witness(tmp_path: Path, keys: Keys) -> Iterator[tuple[Path, Path, str]]:
    """A root published to ``out`` and pushed to a witness that serves ``out``; the root
    published again, so ``out`` serves the cosigned note."""
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, keys.robot_key, range(600))
    assert cli("publish", root, "--out", out).returncode == 0
    process, url = serve(keys, tmp_path / "state", out)
    try:
        pushed = run_cli("witness", "push", str(root), "--witness", url)
        assert pushed.returncode == 0, pushed.stdout + pushed.stderr
        done = cli("publish", root, "--out", out, "--json")
        assert json.loads(done.stdout)["robots"][0]["cosigned_by"] == [WITNESS_NAME]
        yield root, out, url
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=20) == 0
        if process.stderr is not None:
            process.stderr.close()


def get(url: str, path: str) -> tuple[int, bytes, dict[str, str]]:
    """GET ``path`` exactly as written (no client-side normalising of ``..``)."""
    host, port = url.removeprefix("http://").split(":")
    connection = http.client.HTTPConnection(host, int(port), timeout=20)
    try:
        connection.request("GET", path)
        response = connection.getresponse()
        return response.status, response.read(), dict(response.getheaders())
    finally:
        connection.close()


def test_the_go_client_reads_the_tree_and_the_cosignature_from_the_witness(
    witness: tuple[Path, Path, str], keys: Keys, go_client: GoClient
) -> None:
    _root, _out, url = witness
    request = {"url": f"{url}/tiles/amr-7", "vkey": keys.robot_vkey, "index": 345,
               "witness_vkey": keys.witness_verifier.vkey}  # fmt: skip
    done = go_client(request)
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    assert answer["size"] == 600 and WITNESS_NAME in answer["signers"]
    assert any(u.endswith("/tiles/amr-7/tile/entries/001") for u in answer["fetched"])


def test_published_files_are_served_with_their_headers(witness: tuple[Path, Path, str]) -> None:
    _root, out, url = witness
    status, body, headers = get(url, "/tiles/amr-7/checkpoint")
    assert status == 200 and body == (out / "amr-7" / "checkpoint").read_bytes()
    assert headers["Content-Type"].startswith("text/plain")
    assert headers["Cache-Control"] == "no-cache"
    status, body, headers = get(url, "/tiles/amr-7/tile/0/002.p/88")
    assert status == 200 and body == (out / "amr-7" / "tile/0/002.p/88").read_bytes()
    assert "immutable" in headers["Cache-Control"]


def test_nothing_but_a_published_tree_file_is_served(
    witness: tuple[Path, Path, str], tmp_path: Path
) -> None:
    _root, out, url = witness
    secret = tmp_path / "secret"
    secret.mkdir()
    (secret / "checkpoint").write_bytes(b"SECRET")
    (secret / "000").write_bytes(b"SECRET")
    (out / "amr-7" / "notes.txt").write_bytes(b"SECRET")
    (out / "amr-7" / "tile/0/005").symlink_to(secret / "000")
    (out / "evil").symlink_to(secret)
    (out / "amr-7" / "tile/5").symlink_to(secret)
    os.mkfifo(out / "amr-7" / "tile/0/006")
    refused = [
        "/tiles/amr-7/notes.txt",  # not a name of the tree
        "/tiles/amr-7/tile/0/005",  # a link to a file outside
        "/tiles/evil/checkpoint",  # a robot folder that is a link
        "/tiles/amr-7/tile/5/000",  # a level folder that is a link
        "/tiles/amr-7/tile/0/006",  # a FIFO: answered at once, never waited on
        "/tiles/amr-7/../../secret/checkpoint",
        "/tiles/../secret/checkpoint",
        "/tiles/amr-7/tile/0/%2e%2e/%2e%2e/secret/000",
        "/tiles/amr-7/tile/0/000?x=1",
        "/tiles/amr-7/tile/0/002.p/256",  # no such width
        "/tiles/amr-7/tile/0/003",  # a name of the grammar the tree does not hold
        "/tiles//amr-7/checkpoint",
    ]
    for path in refused:
        status, body, _headers = get(url, path)
        assert (status, b"SECRET" in body) == (404, False), path
    assert get(url, "/tiles/amr-7/tile/0/000")[0] == 200  # the server still answers


def test_a_tiles_folder_that_is_not_one_is_refused(tmp_path: Path, keys: Keys) -> None:
    done = run_cli("witness", "serve", "--listen", "127.0.0.1:0", "--state",
                   str(tmp_path / "state"), "--key", str(keys.witness_key), "--log",
                   keys.robot_vkey, "--tiles", str(tmp_path / "missing"))  # fmt: skip
    one_line(done, 2, "--tiles", "not a folder")
