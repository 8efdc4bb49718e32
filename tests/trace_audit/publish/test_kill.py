"""A first ``publish`` of a large log killed for real (SIGKILL at a random point, a process
started as an operator would), then run again: the second run completes, the published tree
is the one a run never killed publishes (and the outside Go client verifies it), and the
unfinished files the killed run left are removed, but only those the tool can prove are its
own: named as it names them beside a name of the tree, inside the robot's published folder,
by a process that no longer runs. Look-alikes planted beside them stay."""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.outside import REPO, cli, snapshot
from tests.trace_audit.publish.conftest import GoClient, RobotKey
from tests.trace_audit.witness.test_tail import write

CYCLES = 5000  # 19 full tiles and 500 signed checkpoints: a run of seconds, fsync-bound


@dataclass
class Killed:
    root: Path
    out: Path
    seed: int
    kills: int
    leftovers: list[str]
    planted: list[str]
    report: dict[str, Any]


def _start_publish(root: Path, out: Path) -> subprocess.Popen[bytes]:
    return subprocess.Popen(
        [sys.executable, "-m", "trace_audit.cli", "publish", str(root), "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )


def _wait_for_tiles(out: Path, process: subprocess.Popen[bytes]) -> None:
    deadline = time.monotonic() + 120
    while not (out / "amr-7" / "tile").exists() and process.poll() is None:
        assert time.monotonic() < deadline, "publish wrote no tile in 120 s"
        time.sleep(0.005)


def _writing_time(root: Path, out: Path) -> float:
    """How long a whole first run writes after its tree appears, on this machine now: the
    kill is drawn within it, so it lands mid-run on a fast machine as on a loaded one."""
    process = _start_publish(root, out)
    _wait_for_tiles(out, process)
    tiles_at = time.monotonic()
    assert process.wait(timeout=300) == 0
    shutil.rmtree(out)
    return time.monotonic() - tiles_at


def _killed_first_run(
    root: Path, out: Path, rng: random.Random, writing_s: float
) -> tuple[int, list[str]]:
    """Start publish, SIGKILL it a random time after its tree appears, within the time a
    whole run writes; its pid and the unfinished files it left (none when it ended before
    the kill: the caller tries again)."""
    process = _start_publish(root, out)
    _wait_for_tiles(out, process)
    time.sleep(rng.uniform(0.0, 0.9 * writing_s))
    process.send_signal(signal.SIGKILL)
    code = process.wait(timeout=20)
    if code != -signal.SIGKILL:
        return process.pid, []
    return process.pid, sorted(str(p.relative_to(out)) for p in out.rglob("*.partial"))


def _plant(out: Path, dead_pid: int, outside: Path) -> list[str]:
    """Files like a killed run's that the tool cannot prove are its own (their paths)."""
    folder = out / "amr-7" / "tile" / "0"
    planted = {
        folder / f".000.{os.getpid()}.0.partial": b"a live process's",
        folder / "notes.partial": b"not its naming",
        folder / f".notes.{dead_pid}.0.partial": b"beside no name of the tree",
        folder / f".003.{10**20}.0.partial": b"no process id: os.kill would overflow",
        out / f".000.{dead_pid}.0.partial": b"beside no robot's folder",
    }
    for path, data in planted.items():
        path.write_bytes(data)
    (outside / "kept.bin").write_bytes(b"outside the tree")
    link = folder / f".001.{dead_pid}.9.partial"
    link.symlink_to(outside / "kept.bin")
    (folder / f".002.{dead_pid}.9.partial").mkdir()
    paths = [*planted, link, folder / f".002.{dead_pid}.9.partial"]
    return sorted(str(p.relative_to(out)) for p in paths)


@pytest.fixture(scope="module")
def killed(tmp_path_factory: pytest.TempPathFactory, robot_key: RobotKey) -> Killed:
    base = tmp_path_factory.mktemp("killed")
    root, out, outside = base / "root", base / "out", base / "outside"
    outside.mkdir()
    write(root, robot_key.private, range(CYCLES))
    seed = random.randrange(1 << 32)
    rng = random.Random(seed)
    writing_s = _writing_time(root, out)
    for attempt in range(5):  # a kill nearly always lands while a file is being written
        kills = attempt + 1
        shutil.rmtree(out, ignore_errors=True)
        pid, leftovers = _killed_first_run(root, out, rng, writing_s)
        if leftovers and not (out / "amr-7" / "checkpoint").exists():
            break
    else:
        pytest.fail(f"5 kills (seed {seed}) left no unfinished file of a first run")
    planted = _plant(out, pid, outside)
    done = cli("publish", root, "--out", out, "--json")
    assert done.returncode == 0, (seed, done.stderr)
    report = json.loads(done.stdout)["robots"][0]
    return Killed(root, out, seed, kills, leftovers, planted, report)


def test_the_second_run_removes_the_killed_runs_leftovers_and_nothing_else(
    killed: Killed,
) -> None:
    out = killed.out
    assert killed.report["removed"] == len(killed.leftovers), killed.seed
    assert not [p for p in killed.leftovers if os.path.lexists(out / p)], killed.seed
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*.partial")) == killed.planted
    link = next(out / p for p in killed.planted if (out / p).is_symlink())
    assert link.read_bytes() == b"outside the tree"  # neither the link nor its target removed


def test_the_tree_is_what_a_run_never_killed_publishes(killed: Killed, tmp_path: Path) -> None:
    fresh = tmp_path / "fresh"
    done = cli("publish", killed.root, "--out", fresh, "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["robots"][0]["removed"] == 0
    published = {k: v for k, v in snapshot(killed.out).items() if k not in killed.planted}
    assert published == snapshot(fresh), f"seed {killed.seed}, {killed.kills} kill(s)"
    assert killed.report["tree_size"] == CYCLES


def test_the_go_client_verifies_the_tree_after_the_kill(
    killed: Killed,
    robot_key: RobotKey,
    go_client: GoClient,
    static_server: Callable[[Path], str],
) -> None:
    url = static_server(killed.out) + "/amr-7"
    index = random.Random(killed.seed).randrange(CYCLES)
    done = go_client({"url": url, "vkey": robot_key.vkey, "index": index})
    assert done.returncode == 0, (killed.seed, done.stderr)
    answer = json.loads(done.stdout)
    assert answer["size"] == CYCLES and answer["inclusion"]
