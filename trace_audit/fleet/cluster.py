"""A Dask cluster as a ``concurrent.futures.Executor``: the one door to ``dask.distributed``.

``index``, ``metrics`` and ``verify`` fan segments out over any ``Executor``; given a
scheduler address they get this one instead of local processes. Workers open segments by
the paths the client names, so every worker must see the logs (and the index directory)
at the same paths: shared storage (NFS, a cluster file system) is assumed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from concurrent.futures import Executor

from trace_runtime.errors import UsageError

__all__ = ["dask_executor"]

CONNECT_TIMEOUT_S = 5


@contextlib.contextmanager
def dask_executor(address: str) -> Iterator[Executor]:
    """Connect to the Dask scheduler at ``address`` (``tcp://host:8786``) and yield an
    executor on its workers; ``UsageError`` when it cannot be reached or has no workers."""
    try:
        from distributed import Client
    except ImportError as err:
        raise UsageError(
            "--scheduler needs dask.distributed (pip install 'trace-audit[fleet]')"
        ) from err
    _check_is_scheduler(address)
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)  # type: ignore[no-untyped-call]
    except (OSError, ValueError) as err:  # the probe passed: the scheduler went away since
        raise UsageError(
            f"cannot reach the Dask scheduler at {address}: {_first_line(err)}"
        ) from err
    with client:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as err:
            raise UsageError(f"the Dask scheduler at {address} has no workers") from err
        # pure=False: a task names a file by path, whose bytes may change between two
        # calls; Dask must run it again rather than hand back a result it still holds.
        yield client.get_executor(pure=False)  # type: ignore[no-untyped-call]


def _check_is_scheduler(address: str) -> None:
    """Ask ``address`` who it is, within a bounded time, before a ``Client`` is made.

    ``Client`` waits forever on a listener that accepts and says nothing, reads another
    protocol's bytes as a frame length (an HTTP server at the dashboard port 8787 makes it
    allocate exabytes), and a half-made client prints a traceback when collected. One
    ``identity`` round trip with a deadline tells a scheduler from all of these."""
    import asyncio

    from distributed.comm import connect  # type: ignore[attr-defined]

    async def identity() -> object:
        comm = await connect(address, timeout=CONNECT_TIMEOUT_S)  # type: ignore[no-untyped-call]
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        reply = asyncio.run(asyncio.wait_for(identity(), 2 * CONNECT_TIMEOUT_S))
    except TimeoutError as err:
        raise UsageError(
            f"cannot reach the Dask scheduler at {address}: no answer within "
            f"{2 * CONNECT_TIMEOUT_S} s (is it the scheduler's port, usually 8786?)"
        ) from err
    except (OSError, ValueError) as err:  # refused, unroutable, or not an address
        raise UsageError(
            f"cannot reach the Dask scheduler at {address}: {_first_line(err)}"
        ) from err
    except _foreign_reply_errors() as err:
        raise UsageError(
            f"cannot reach the Dask scheduler at {address}: something else answers there "
            "(is it the scheduler's port, usually 8786?)"
        ) from err
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise UsageError(
            f"cannot reach the Dask scheduler at {address}: something else answers there"
        )


def _foreign_reply_errors() -> tuple[type[BaseException], ...]:
    """What reading another protocol's bytes as Dask frames raises besides OSError and
    ValueError: a frame length read from them asks for exabytes (MemoryError), a short frame
    fails to unpack (struct.error), a body fails to decode (msgpack) or is not a message."""
    import struct

    from msgpack import UnpackException  # type: ignore[import-untyped]

    return (MemoryError, struct.error, EOFError, KeyError, TypeError, UnpackException)


def _first_line(err: BaseException) -> str:
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__
