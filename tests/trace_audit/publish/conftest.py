"""A published tree seen from outside: the robot's key, a static web server (the stdlib's
``python -m http.server``, a real process) over the published folder, and the outside Go
client (go_client/main.go) built with Debian's Go and x/mod, as the Go oracle tests build
theirs; without them the Go tests skip, saying why."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from trace_runtime.tlog.keys import generate_keypair, load_public_key
from trace_runtime.tlog.signed_note import verifier_key

CLIENT_SOURCE = Path(__file__).parent / "go_client" / "main.go"
GOPATH = Path(os.environ.get("TRACE_GOPATH", "/usr/share/gocode"))
PACKAGES = ("golang.org/x/mod/sumdb/note", "golang.org/x/mod/sumdb/tlog")
ORIGIN = "trace.local/amr-7"


@dataclass
class RobotKey:
    private: Path
    public: Path

    @property
    def vkey(self) -> str:
        return verifier_key(ORIGIN, load_public_key(self.public).raw)


@pytest.fixture(scope="module")
def robot_key(tmp_path_factory: pytest.TempPathFactory) -> RobotKey:
    pair = generate_keypair(tmp_path_factory.mktemp("keys"), name="amr-7")
    return RobotKey(pair.private_path, pair.public_path)


@pytest.fixture
def static_server(tmp_path: Path) -> Iterator[Callable[[Path], str]]:
    """Serve a folder with ``python -m http.server`` on a free port; its base URL."""
    started: list[subprocess.Popen[str]] = []

    def serve(folder: Path) -> str:
        process = subprocess.Popen(
            [sys.executable, "-u", "-m", "http.server", "0", "--bind", "127.0.0.1", "-d",
             str(folder)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )  # fmt: skip
        started.append(process)
        assert process.stdout is not None
        line = process.stdout.readline()  # "Serving HTTP on 127.0.0.1 port N (...) ..."
        assert " port " in line, line
        return f"http://127.0.0.1:{line.split(' port ', 1)[1].split()[0]}"

    yield serve
    for process in started:
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=20)
        if process.stdout is not None:
            process.stdout.close()


GoClient = Callable[[dict[str, Any]], subprocess.CompletedProcess[str]]


@pytest.fixture(scope="session")
def go_client(tmp_path_factory: pytest.TempPathFactory) -> GoClient:
    """Run the built outside client on one request (its answer: exit code, JSON, stderr)."""
    go = shutil.which("go")
    if go is None:
        pytest.skip("go not found: install Debian's golang-go (scripts/install-go.sh)")
    missing = [p for p in PACKAGES if not (GOPATH / "src" / p).is_dir()]
    if missing:
        pytest.skip(f"go packages not found under {GOPATH}/src: {', '.join(missing)} "
                    "(Debian's golang-golang-x-mod-dev; scripts/install-go.sh)")  # fmt: skip
    where = tmp_path_factory.mktemp("go-client")
    binary = where / "client"
    env = {**os.environ, "GOPATH": str(GOPATH), "GO111MODULE": "off",
           "GOCACHE": str(where / "cache"), "GOFLAGS": "", "CGO_ENABLED": "0"}  # fmt: skip
    built = subprocess.run(
        [go, "build", "-o", str(binary), str(CLIENT_SOURCE)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert built.returncode == 0, f"go build of the outside client failed:\n{built.stderr}"

    def run(request: dict[str, Any]) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(binary)],
            input=json.dumps(request),
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )

    return run
