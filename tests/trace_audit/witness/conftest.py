"""A real ``trace-audit witness serve`` process on 127.0.0.1 (a free port, a temp state
folder), and the keys: the robot's checkpoint key and the witness's cosigning key."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from trace_runtime.tlog.keys import generate_keypair, load_public_key, load_signer
from trace_runtime.tlog.signed_note import COSIGNATURE, NoteSigner, NoteVerifier, verifier_key

ROOT = Path(__file__).resolve().parents[3]
ORIGIN = "trace.local/amr-7"
WITNESS_NAME = "trace.local/witness"


def run_cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "trace_audit.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
        check=False,
    )


@dataclass
class Keys:
    folder: Path
    robot_key: Path
    robot_pub: Path
    witness_key: Path
    witness_pub: Path

    @property
    def robot_signer(self) -> NoteSigner:
        signer = load_signer(self.robot_key)
        return NoteSigner(ORIGIN, signer, signer.public_key.raw)

    @property
    def robot_vkey(self) -> str:
        return verifier_key(ORIGIN, load_public_key(self.robot_pub).raw)

    @property
    def witness_verifier(self) -> NoteVerifier:
        return NoteVerifier.of(WITNESS_NAME, load_public_key(self.witness_pub).raw, COSIGNATURE)


@pytest.fixture(scope="module")
def keys(tmp_path_factory: pytest.TempPathFactory) -> Keys:
    folder = tmp_path_factory.mktemp("keys")
    robot = generate_keypair(folder, name="amr-7")
    witness = generate_keypair(folder, name="witness")
    return Keys(folder, robot.private_path, robot.public_path, witness.private_path,
                witness.public_path)  # fmt: skip


@dataclass
class WitnessProcess:
    """One ``witness serve`` process; ``restart`` stops it (SIGTERM, exit 0) and starts
    another on the same state folder."""

    state: Path
    keys: Keys
    logs: list[str]
    url: str = ""
    process: subprocess.Popen[str] | None = None
    exit_codes: list[int] = field(default_factory=list)

    def start(self) -> None:
        args = [sys.executable, "-m", "trace_audit.cli", "witness", "serve", "--listen",
                "127.0.0.1:0", "--state", str(self.state), "--key", str(self.keys.witness_key),
                "--name", WITNESS_NAME]  # fmt: skip
        for vkey in self.logs:
            args += ["--log", vkey]
        self.process = subprocess.Popen(
            args,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        assert self.process.stderr is not None
        line = self.process.stderr.readline()
        assert "listening on " in line, line
        self.url = line.split("listening on ", 1)[1].split()[0]

    def stop(self) -> int:
        assert self.process is not None
        self.process.send_signal(signal.SIGTERM)
        code = self.process.wait(timeout=20)
        if self.process.stderr is not None:
            self.process.stderr.close()
        self.exit_codes.append(code)
        self.process = None
        return code

    def restart(self) -> None:
        self.stop()
        self.start()


@pytest.fixture
def witness_process(tmp_path: Path, keys: Keys) -> Iterator[Callable[..., WitnessProcess]]:
    started: list[WitnessProcess] = []

    def start(*logs: str, state: Path | None = None) -> WitnessProcess:
        w = WitnessProcess(state or tmp_path / f"state{len(started)}", keys,
                           list(logs) or [keys.robot_vkey])  # fmt: skip
        w.start()
        started.append(w)
        return w

    yield start
    for w in started:
        if w.process is not None:
            assert w.stop() == 0
