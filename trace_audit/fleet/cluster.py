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
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)  # type: ignore[no-untyped-call]
    except (OSError, TimeoutError, ValueError) as err:
        raise UsageError(f"cannot reach the Dask scheduler at {address}: {err}") from err
    with client:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as err:
            raise UsageError(f"the Dask scheduler at {address} has no workers") from err
        # pure=False: a task names a file by path, whose bytes may change between two
        # calls; Dask must run it again rather than hand back a result it still holds.
        yield client.get_executor(pure=False)  # type: ignore[no-untyped-call]
