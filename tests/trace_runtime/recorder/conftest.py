"""Real processes for the recorder's tests: ``trace-recorder serve`` started as a program,
and the C++ robot (``build/cpp_robot``, built by scripts/build-cpp.sh when absent)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.outside import cli

REPO = Path(__file__).resolve().parents[3]
CPP_ROBOT = REPO / "build" / "cpp_robot"
_ENV = {**os.environ, "PYTHONPATH": str(REPO)}


class RecorderProcess:
    """``trace-recorder serve --root ROOT --socket SOCKET`` running in its own process."""

    def __init__(self, root: Path, socket_path: Path, *extra: str) -> None:
        self.root = root
        self.socket = socket_path
        self.extra = extra
        self.proc: subprocess.Popen[str] | None = None
        self.stderr_lines: list[str] = []

    def start(self, timeout_s: float = 20.0) -> RecorderProcess:
        command = [sys.executable, "-m", "trace_runtime.recorder.cli", "serve"]
        command += ["--root", str(self.root), "--socket", str(self.socket), *self.extra]
        self.proc = subprocess.Popen(
            command, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=_ENV
        )
        assert self.proc.stderr is not None
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:  # its first line says where it listens
            line = self.proc.stderr.readline()
            self.stderr_lines.append(line)
            if "listening on" in line:
                return self
            if not line:
                break
        raise AssertionError(f"the recorder did not start: {self.stderr_lines}")

    def stop(self, timeout_s: float = 30.0) -> tuple[int, str]:
        """SIGTERM; the exit code and everything it wrote on stderr."""
        assert self.proc is not None
        self.proc.send_signal(signal.SIGTERM)
        _, rest = self.proc.communicate(timeout=timeout_s)
        return self.proc.returncode, "".join(self.stderr_lines) + rest

    def kill(self) -> None:
        assert self.proc is not None
        self.proc.kill()
        self.proc.communicate(timeout=10)

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.kill()


@pytest.fixture
def recorder(tmp_path: Path) -> Iterator[RecorderProcess]:
    """A started recorder writing ``tmp_path/root`` on ``tmp_path/rec.sock``."""
    process = RecorderProcess(tmp_path / "root", tmp_path / "rec.sock")
    try:
        yield process.start()
    finally:
        process.close()


@pytest.fixture(scope="session")
def cpp_robot() -> Path:
    """The C++ robot, built with the script CI uses when it is not there yet."""
    if not CPP_ROBOT.exists():
        built = subprocess.run(
            ["bash", str(REPO / "scripts" / "build-cpp.sh")],
            capture_output=True,
            text=True,
            check=False,
            timeout=600,
        )
        assert built.returncode == 0, built.stderr
    return CPP_ROBOT


def run_cpp_robot(
    binary: Path, socket_path: Path, robot_id: str, cycles: int, hz: float, *extra: str
) -> tuple[dict[str, float], dict[str, float]]:
    """Run the C++ robot to its end; its last line and the line before, as numbers."""
    command = [str(binary), "--socket", str(socket_path), "--robot-id", robot_id]
    command += ["--cycles", str(cycles), "--hz", str(hz), *extra]
    done = subprocess.run(command, capture_output=True, text=True, check=False, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    return _pairs(lines[-1]), _pairs(lines[-2])


def _pairs(line: str) -> dict[str, float]:
    words = line.split()
    return {words[i]: float(words[i + 1]) for i in range(0, len(words), 2)}


# What differs between two logs of the same cycles: where the files are, and how long logging
# and measuring took.
_RUN_SPECIFIC = {"logs", "segments", "elapsed_s", "cycles_per_s", "logging_time", "logging_cost"}


def comparable_metrics(root: Path) -> dict[str, Any]:
    """``trace-audit metrics ROOT --json`` without what differs from run to run."""
    done = cli("metrics", root, "--json")
    assert done.returncode == 0, done.stderr
    result: dict[str, Any] = json.loads(done.stdout)
    result["table_ii"].pop("time_per_cycle")
    return {k: v for k, v in result.items() if k not in _RUN_SPECIFIC}
