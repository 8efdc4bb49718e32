"""Edges of a log root met from the outside: a segment file where a root belongs, a folder
holding only a file that is not MCAP, a witness that cannot start, and a warning that one
command would print twice."""

from __future__ import annotations

import socket
from pathlib import Path

from tests.outside import cli, one_line
from tests.trace_audit.conftest import write_log
from trace_runtime.tlog.keys import generate_keypair


def test_a_segment_file_given_as_a_root_says_what_it_is(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root")
    segment = next((root / "hot").glob("*.mcap"))
    for args in (("catalog", segment), ("compact", segment, "--tier", "cold")):
        one_line(cli(*args), 3, str(segment), "a segment file, not a log root", "hot/")
    one_line(cli("catalog", tmp_path / "nope"), 3, "no such directory")


def test_a_folder_of_only_a_file_that_is_not_mcap_is_unreadable(tmp_path: Path) -> None:
    (tmp_path / "root" / "hot").mkdir(parents=True)
    (tmp_path / "root" / "hot" / "x.mcap").write_text("not a log\n", encoding="utf-8")
    one_line(cli("tail", tmp_path / "root"), 3, "x.mcap", "not an MCAP file")
    done = cli("catalog", tmp_path / "root")
    one_line(done, 3, "no readable segment", "x.mcap")
    assert "x.mcap" in done.stdout  # the listing still names what could not be read
    (tmp_path / "empty").mkdir()
    one_line(cli("tail", tmp_path / "empty"), 3, "no .mcap segments")
    assert cli("catalog", tmp_path / "empty").returncode == 0  # an empty root is a root


def test_a_witness_that_cannot_listen_leaves_no_state_behind(tmp_path: Path) -> None:
    robot = generate_keypair(tmp_path / "keys", name="amr-7")
    witness = generate_keypair(tmp_path / "keys", name="witness")
    vkey = cli("witness", "vkey", "--key", robot.public_path, "--origin", "trace.local/amr-7")
    assert vkey.returncode == 0, vkey.stderr
    state = tmp_path / "state"
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        done = cli(
            "witness", "serve", "--listen", f"127.0.0.1:{port}", "--state", state,
            "--key", witness.private_path, "--log", vkey.stdout.strip(),
        )  # fmt: skip
    one_line(done, 2, "cannot listen")
    assert not state.exists() or list(state.iterdir()) == []


def test_a_recovered_segment_is_said_once_per_command(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root", finish=False)
    done = cli("verify", root, "--witness", "local")
    assert "Traceback" not in done.stderr, done.stderr
    assert done.stderr.count("no footer") == 1, done.stderr
