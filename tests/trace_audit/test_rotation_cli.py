"""Key rotation from the command line, from the outside: ``trace-sim run --next-key`` and
``trace-recorder serve --next-key`` rotate a robot once however often they are started
again (``LoggerConfig.next_key``), and ``verify --key OLD`` says where the rotation was
and names both keys by key id and by C2SP verifier key, in text and in JSON. A continued
sim robot's clock goes on from its last cycle instead of restarting at 0."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.outside import REPO, cli, one_line
from tests.trace_runtime.recorder.conftest import RecorderProcess
from trace_runtime.recorder import RemoteLogger
from trace_runtime.tlog.keys import KeyPair, generate_keypair, load_public_key
from trace_runtime.tlog.signed_note import verifier_key


def sim(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "evaluation.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
    )


@pytest.fixture
def keys(tmp_path: Path) -> dict[str, KeyPair]:
    return {n: generate_keypair(tmp_path / "keys", name=n) for n in ("old", "new")}


def verify_json(root: Path, public: Path) -> tuple[int, dict[str, Any]]:
    done = cli("verify", root, "--key", public, "--json")
    assert done.returncode in (0, 1), done.stderr
    return done.returncode, json.loads(done.stdout)


def test_sim_next_key_rotates_once_and_verify_says_where(
    tmp_path: Path, keys: dict[str, KeyPair]
) -> None:
    old, new = keys["old"], keys["new"]
    root = tmp_path / "logs"
    common = ("run", "--duration", "30s", "--faults", "off", "--out", root)
    assert sim(*common, "--key", old.private_path).returncode == 0
    # The same command twice: the second run finds the rotation in the chain, announces
    # nothing and signs with the new key (the old one would be a retired key's signature).
    for _ in range(2):
        done = sim(*common, "--key", old.private_path, "--next-key", new.private_path)
        assert done.returncode == 0, done.stderr
    code, report = verify_json(root, old.public_path)
    assert (code, report["findings"]) == (0, [])
    (robot,) = report["robots"]
    (rotation,) = robot["key_rotations"]
    vkey = verifier_key("trace.local/amr-01", load_public_key(new.public_path).raw)
    assert rotation["from_key_id"] == old.key_id and rotation["to_key_id"] == new.key_id
    assert rotation["to_vkey"] == vkey and robot["announced_keys"] == [vkey]
    assert 300 <= rotation["cycle"] < 600  # announced in the second run's 300 cycles
    text = cli("verify", root, "--key", old.public_path, "--plain").stdout
    line = " ".join(text.split())  # the plain table wraps long values
    assert (
        f"key rotated at cycle {rotation['cycle']}, announced by key {old.key_id[:16]}…, "
        f"to key {new.key_id[:16]}… (vkey {'+'.join(vkey.split('+')[:2])})"
    ) in line
    # The new key alone does not vouch for what the old key signed.
    assert verify_json(root, new.public_path)[0] == 1


def test_sim_next_key_usage_errors(tmp_path: Path, keys: dict[str, KeyPair]) -> None:
    out = tmp_path / "logs"
    new = keys["new"].private_path
    one_line(sim("run", "--cycles", "3", "--out", out, "--next-key", new), 2, "needs --key")
    one_line(sim("run", "--cycles", "3", "--out", out, "--key", new, "--next-key", new), 2,
             "nothing to rotate to")  # fmt: skip


def _send(socket: Path, first: int, cycles: int) -> None:
    with RemoteLogger(socket, robot_id="amr-1", period_s=0.01) as remote:
        for i in range(first, first + cycles):
            remote.log_cycle(i * 10_000_000, action={"command": "GO", "rationale": {"text": "ok"}})
        assert remote.flush()


def test_recorder_next_key_rotates_once_across_reconnects_and_restarts(
    tmp_path: Path, keys: dict[str, KeyPair]
) -> None:
    old, new = keys["old"], keys["new"]
    root, sock = tmp_path / "root", tmp_path / "rec.sock"
    args = ("--key", str(old.private_path))
    first = RecorderProcess(root, sock, *args).start()
    _send(sock, 0, 50)
    assert first.stop()[0] == 0
    rotating = ("--key", str(old.private_path), "--next-key", str(new.private_path))
    for start in (50, 100):  # a restart of the same service, with the same command line
        second = RecorderProcess(root, sock, *rotating).start()
        _send(sock, start, 25)
        _send(sock, start + 25, 25)  # the robot reconnects: a new logger, no new rotation
        assert second.stop()[0] == 0
    code, report = verify_json(root, old.public_path)
    assert (code, report["findings"]) == (0, []), report["findings"]
    (robot,) = report["robots"]
    assert robot["cycles_valid"] == 150
    assert [(r["from_key_id"], r["to_key_id"]) for r in robot["key_rotations"]] == [
        (old.key_id, new.key_id)
    ]


def test_recorder_next_key_without_key_is_a_usage_error(
    tmp_path: Path, keys: dict[str, KeyPair]
) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "trace_runtime.recorder.cli", "serve", "--root", tmp_path / "r",
         "--socket", tmp_path / "s", "--next-key", keys["new"].private_path],
        capture_output=True, text=True, check=False, timeout=60,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    one_line(done, 2, "--next-key needs --key")


def test_a_continued_sim_robot_s_clock_goes_on(tmp_path: Path) -> None:
    root = tmp_path / "fleet"
    for _ in range(2):
        done = sim(
            "run", "--duration", "30s", "--faults", "off", "--robot-id", "amr-1", "--out", root
        )
        assert done.returncode == 0, done.stderr
    report = json.loads(cli("verify", root, "--json").stdout)
    (robot,) = report["robots"]
    # 600 cycles at 10 Hz: the second run's first cycle is one period after the first's last.
    assert (robot["first_cycle"], robot["last_cycle"]) == (0, 599)
    assert (robot["start_ns"], robot["end_ns"]) == (0, 599 * 100_000_000)
    assert "clock_restart" not in {n["kind"] for n in report["notes"]}
    # An explicit --start before that is the operator's: the clock restarts, and says so.
    assert sim("run", "--cycles", "20", "--start", "0", "--robot-id", "amr-1", "--out",
               root).returncode == 0  # fmt: skip
    report = json.loads(cli("verify", root, "--json").stdout)
    assert "clock_restart" in {n["kind"] for n in report["notes"]}


def test_a_continued_wall_clock_robot_stays_on_the_wall_clock(tmp_path: Path) -> None:
    root = tmp_path / "fleet"
    start = ("--start", "2026-05-04T06:00:00Z")
    assert sim("run", "--duration", "10s", *start, "--out", root).returncode == 0
    assert sim("run", "--duration", "10s", "--out", root).returncode == 0
    (robot,) = json.loads(cli("verify", root, "--json").stdout)["robots"]
    assert robot["clock"] == "system"
    t0 = 1_777_874_400 * 1_000_000_000  # 2026-05-04T06:00:00Z
    assert (robot["start_ns"], robot["end_ns"]) == (t0, t0 + 199 * 100_000_000)
