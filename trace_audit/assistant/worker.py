"""Where the questions run: one worker process, killed when a call outlives its time.

A thread cannot be stopped in Python: a question that runs too long would go on reading
and holding memory after its caller was told it timed out, and every later call would
queue behind it. A process can be, so each call runs in a worker process (spawned, not
forked: the server's event loop runs threads) and one that overruns is killed and
replaced. Calls run one at a time (the machine's cores belong to the investigator), so a
call's time is its own, not the queue's.

The worker writes nothing on stdout: over stdio, stdout is the protocol's channel.
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from multiprocessing.pool import Pool
from typing import Any

import anyio
import anyio.to_thread

from trace_audit.assistant.questions import ask
from trace_runtime.errors import UsageError

__all__ = ["CallTimeoutError", "Worker"]


class CallTimeoutError(UsageError):
    """A question did not finish within the call's time; its worker was killed. A usage
    error: the question asks for too much at once (a narrower one fits)."""


def _quiet_stdout() -> None:
    """In the worker: stdout (fd 1 and ``sys.stdout``) goes to stderr."""
    os.dup2(2, 1)
    sys.stdout = sys.stderr


class Worker:
    """One worker process that answers ``questions.ask``, within ``timeout_s`` a call."""

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self._pool: Pool | None = None
        self._lock = anyio.Lock()

    def _started(self) -> Pool:
        """The worker pool, started now if it is not running (at the server's start, so the
        worker's interpreter starts while the client connects; after a kill, on the next
        call)."""
        if self._pool is None:
            context = multiprocessing.get_context("spawn")
            self._pool = context.Pool(processes=1, initializer=_quiet_stdout)
        return self._pool

    async def ask(self, name: str, args: dict[str, Any], limit: int) -> tuple[str, Any, Any]:
        """``questions.ask(name, args, limit)`` in the worker; ``CallTimeoutError`` when it
        runs past the call's time (the worker is then killed, and the next call starts a
        new one)."""
        async with self._lock:
            pool = self._started()
            pending = pool.apply_async(ask, (name, args, limit))
            try:
                result: tuple[str, Any, Any] = await anyio.to_thread.run_sync(
                    pending.get, self.timeout_s
                )
            except multiprocessing.TimeoutError:
                self._pool = None
                await anyio.to_thread.run_sync(pool.terminate)
                raise CallTimeoutError(
                    f"{name} did not finish within {self.timeout_s:g} s and was stopped"
                ) from None
            return result

    def start(self) -> None:
        """Start the worker process before the first call."""
        self._started()

    def close(self) -> None:
        """Stop the worker (the server is leaving)."""
        if self._pool is not None:
            self._pool.terminate()
            self._pool = None
