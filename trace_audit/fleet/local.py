"""A real Dask cluster on this machine: a ``dask scheduler`` and ``dask worker`` processes.

What the fleet tests and ``bench/bench_fleet.py`` run ``--scheduler`` against, and a way to
try it on one machine without a cluster: separate processes talking TCP on localhost, as on
a real cluster, not Dask's in-process ``LocalCluster``.

    with LocalDask(work_dir) as cluster:
        cluster.add_worker()
        compute_metrics([root], executor=...)  # via dask_executor(cluster.address)
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import TracebackType
from typing import IO

__all__ = ["LocalDask", "free_port"]

START_TIMEOUT_S = 60.0


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on just now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LocalDask:
    """A scheduler on a free localhost port, and the workers added with ``add_worker``.

    Their output goes to ``scheduler.log`` and ``worker-N.log`` in ``work_dir``, which is
    also their working and spill directory. ``pythonpath`` is put first on the processes'
    ``PYTHONPATH`` (a source checkout that is not installed). Leaving the ``with`` block
    stops every process, killing one that does not stop within 20 s."""

    def __init__(self, work_dir: Path, pythonpath: Path | None = None) -> None:
        self.work_dir = work_dir
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        paths = [str(pythonpath)] if pythonpath is not None else []
        if os.environ.get("PYTHONPATH"):
            paths.append(os.environ["PYTHONPATH"])
        # A worker that is a daemon process cannot start the processes a task may start.
        self._env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join(paths),
            "DASK_DISTRIBUTED__WORKER__DAEMON": "False",
        }
        self._procs: list[subprocess.Popen[bytes]] = []
        self._logs: list[IO[bytes]] = []

    def __enter__(self) -> LocalDask:
        self.work_dir.mkdir(parents=True, exist_ok=True)
        try:
            scheduler = self._start(
                "scheduler.log",
                "distributed.cli.dask_scheduler",
                *("--host", "127.0.0.1", "--port", str(self.port)),
                *("--dashboard-address", ":0", "--no-show"),
            )
            self._wait_for_port(scheduler)
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()

    def add_worker(self, threads: int = 1) -> None:
        """Start one more worker process with ``threads`` threads."""
        self._start(
            f"worker-{len(self._procs)}.log",
            "distributed.cli.dask_worker",
            self.address,
            *("--nworkers", "1", "--nthreads", str(threads), "--no-dashboard"),
            *("--local-directory", str(self.work_dir)),
        )

    def close(self) -> None:
        """Stop every process (the workers first), then close their logs."""
        for proc in reversed(self._procs):
            proc.terminate()
        for proc in reversed(self._procs):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for log in self._logs:
            log.close()
        self._procs, self._logs = [], []

    def _start(self, log_name: str, module: str, *args: str) -> subprocess.Popen[bytes]:
        log = (self.work_dir / log_name).open("wb")
        self._logs.append(log)
        proc = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=self._env,
            cwd=self.work_dir,
        )
        self._procs.append(proc)
        return proc

    def _wait_for_port(self, proc: subprocess.Popen[bytes]) -> None:
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise RuntimeError(
                    f"the dask scheduler exited with {proc.returncode} "
                    f"(see {self.work_dir / 'scheduler.log'})"
                )
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            time.sleep(0.2)
        raise TimeoutError(f"the dask scheduler did not listen on port {self.port}")
