"""``--scheduler``: a real ``dask scheduler`` and ``dask worker`` on localhost give the
same metrics JSON and the same index as a local run."""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.trace_audit.conftest import rewrite_segment
from tests.trace_audit.fleet.test_index import _fleet
from trace_audit.fleet.local import LocalDask, free_port
from trace_runtime.encoding.cycles import RawMessage

pytest.importorskip("distributed")

REPO = Path(__file__).resolve().parents[3]
TIMING = ("elapsed_s", "cycles_per_s")


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A scheduler and one worker process (nthreads 1), torn down after the module."""
    with LocalDask(tmp_path_factory.mktemp("dask"), pythonpath=REPO) as cluster:
        cluster.add_worker()
        yield cluster.address


def _cli(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", *args],
        capture_output=True,
        text=True,
        check=False,
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
    )


def _without_timing(text: str) -> dict[str, object]:
    data: dict[str, object] = json.loads(text)
    for key in TIMING:
        data.pop(key)
    return data


def _close(a: object, b: object) -> bool:
    """Equal, floats to 1e-12 (sums added in another order round in the last bits)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_close(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return abs(a - b) <= 1e-12
    return a == b


def test_metrics_on_a_dask_cluster_equal_the_local_json(scheduler: str, tmp_path: Path) -> None:
    """Byte for byte the JSON of local processes (each segment one task, merged in the
    same order); a single-process run adds the same sums in another order, so it agrees
    to 1e-12 with every count exact."""
    root = _fleet(tmp_path / "logs")
    args = ("metrics", str(root), "--by", "robot", "--failures", "--json")
    local = _cli(*args, "--jobs", "2")
    single = _cli(*args)
    remote = _cli(*args, "--scheduler", scheduler)
    for done in (local, single, remote):
        assert done.returncode == 0, done.stderr
    if len(os.sched_getaffinity(0)) >= 2:  # else --jobs 2 runs in one process
        assert _without_timing(remote.stdout) == _without_timing(local.stdout)
    assert _close(_without_timing(remote.stdout), _without_timing(single.stdout))


def test_index_on_a_dask_cluster_equals_the_local_index(scheduler: str, tmp_path: Path) -> None:
    root = _fleet(tmp_path / "logs")
    assert _cli("index", str(root), "--out", str(tmp_path / "local"), "--json").returncode == 0
    remote = _cli("index", str(root), "--out", str(tmp_path / "remote"), "--scheduler", scheduler)
    assert remote.returncode == 0, remote.stderr
    sql = "SELECT * EXCLUDE (explain) FROM decisions ORDER BY robot, cycle"
    rows = [
        _cli("query", str(tmp_path / name), sql, "--json").stdout for name in ("local", "remote")
    ]
    assert json.loads(rows[0]) == json.loads(rows[1])
    assert len(json.loads(rows[0])) == 197


def test_an_unreachable_scheduler_is_a_usage_error(tmp_path: Path) -> None:
    root = _fleet(tmp_path / "logs")
    done = _cli("metrics", str(root), "--scheduler", f"tcp://127.0.0.1:{free_port()}")
    assert done.returncode == 2
    assert done.stderr.startswith("trace-audit: cannot reach the Dask scheduler")
    assert done.stderr.count("\n") == 1


def test_verify_on_a_dask_cluster_equals_the_local_json(scheduler: str, tmp_path: Path) -> None:
    """One task per robot; a tampered cycle in r2 is the same finding either way."""
    root = _fleet(tmp_path / "logs")
    victim = sorted((root / "hot").glob("r2_*.mcap"))[1]
    changed: list[int] = []

    def tamper(msg: RawMessage) -> bytes:
        if msg.topic == "/trace/action" and not changed:
            changed.append(msg.log_time_ns)
            return msg.data.replace(b'"command":"', b'"command":"X', 1)
        return msg.data

    rewrite_segment(victim, tmp_path / "tampered.mcap", tamper)
    (tmp_path / "tampered.mcap").replace(victim)
    assert changed
    local = _cli("verify", str(root), "--json")
    remote = _cli("verify", str(root), "--json", "--scheduler", scheduler)
    assert local.returncode == remote.returncode == 1, (local.stderr, remote.stderr)
    assert json.loads(remote.stdout) == json.loads(local.stdout)
    assert len(json.loads(local.stdout)["robots"]) == 2


def test_relative_paths_on_a_dask_cluster_are_the_clients(scheduler: str, tmp_path: Path) -> None:
    """The workers run in another directory: relative inputs and a relative --out name the
    client's files, so the index lands where the client said and metrics reads the logs."""
    _fleet(tmp_path / "logs")
    done = _cli("index", "logs", "--out", "idx", "--scheduler", scheduler, "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    count = _cli("query", "idx", "SELECT count(*) AS n FROM decisions", "--json", cwd=tmp_path)
    assert json.loads(count.stdout) == [{"n": 197}]
    remote = _cli("metrics", "logs", "--scheduler", scheduler, "--json", cwd=tmp_path)
    local = _cli("metrics", "logs", "--json", cwd=tmp_path)
    assert remote.returncode == local.returncode == 0, remote.stderr
    assert _close(_without_timing(remote.stdout), _without_timing(local.stdout))
    verify = _cli("verify", "logs", "--scheduler", scheduler, "--json", cwd=tmp_path)
    assert verify.returncode == 0, verify.stderr


def _listener(reply: bytes) -> tuple[socket.socket, threading.Thread]:
    """A TCP listener on localhost that is not a Dask scheduler: it answers each
    connection with ``reply`` (bytes of another protocol) and keeps it open."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.5)
    held: list[socket.socket] = []

    def serve() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:  # closed by the test
                break
            with contextlib.suppress(OSError):
                conn.sendall(reply)
            held.append(conn)
        for conn in held:
            conn.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return server, thread


@pytest.mark.parametrize(
    "reply",
    [
        b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n",
        b"",  # accepts and says nothing
        b"\xff" * 64,  # garbage a Dask client would read as a huge frame length
    ],
)
def test_a_scheduler_address_that_is_not_dask_is_one_line(tmp_path: Path, reply: bytes) -> None:
    root = _fleet(tmp_path / "logs")
    server, thread = _listener(reply)
    port = server.getsockname()[1]
    try:
        started = time.monotonic()
        done = _cli("metrics", str(root), "--scheduler", f"tcp://127.0.0.1:{port}", "--json")
        took = time.monotonic() - started
    finally:
        server.close()
        thread.join(5)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("trace-audit: cannot reach the Dask scheduler"), done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stdout == ""
    assert took < 30


@pytest.mark.parametrize("address", ["garbage", "", "http://127.0.0.1:8787"])
def test_a_malformed_scheduler_address_is_one_line(tmp_path: Path, address: str) -> None:
    """No 'Exception ignored in Client.__del__' traceback after the line, and no wait."""
    root = _fleet(tmp_path / "logs")
    started = time.monotonic()
    done = _cli("metrics", str(root), "--scheduler", address)
    assert done.returncode == 2
    assert done.stderr.startswith("trace-audit: cannot reach the Dask scheduler"), done.stderr
    assert done.stderr.count("\n") == 1, done.stderr
    assert time.monotonic() - started < 10
