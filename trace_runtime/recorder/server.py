"""The recorder service: listens on a Unix socket (and optionally on a loopback TCP port),
gives each client its own thread (``trace_runtime.recorder.connection``), and writes each
connected robot through its own ``AuditLogger`` under one log root
(``trace_runtime.recorder.robots``).

The Unix socket is created with mode 0660: open to its owner and group only, so the robots'
processes are given access by group, as for any local service. TCP is for clients that
cannot reach the socket file (a container): loopback only, since the protocol has no
authentication of its own.
"""

from __future__ import annotations

import errno
import ipaddress
import logging
import os
import selectors
import socket
import stat
import threading
from pathlib import Path

from trace_runtime.errors import StorageError, UsageError
from trace_runtime.logger.config import LoggerConfig
from trace_runtime.recorder.connection import Connection, RecorderCounters
from trace_runtime.recorder.protocol import MAX_FRAME_BYTES, encode_frame
from trace_runtime.recorder.robots import Robots

__all__ = ["SOCKET_MODE", "Recorder", "parse_tcp"]

log = logging.getLogger("trace_runtime.recorder")

SOCKET_MODE = 0o660
"""The Unix socket's permissions: read and write for its owner and group, nothing for others."""
_POLL_S = 0.1
_JOIN_S = 10.0  # per connection at close: its logger's bounded close (5 s) and some


def parse_tcp(text: str) -> tuple[str, int]:
    """``HOST:PORT`` of a loopback address (``127.0.0.1:7400``, ``[::1]:7400``); port 0
    asks the system for a free one. ``UsageError`` otherwise."""
    host, sep, port = text.rpartition(":")
    host = host.removeprefix("[").removesuffix("]")
    try:
        address = ipaddress.ip_address(host)
        number = int(port)
    except ValueError as err:
        raise UsageError(f"--tcp {text!r}: give HOST:PORT, e.g. 127.0.0.1:7400") from err
    if not sep or not 0 <= number <= 65535:
        raise UsageError(f"--tcp {text!r}: give HOST:PORT, e.g. 127.0.0.1:7400")
    if not address.is_loopback:
        raise UsageError(
            f"--tcp {text!r}: only a loopback address is allowed (the protocol has no "
            "authentication; reach other hosts through the socket file or a tunnel)"
        )
    return str(address), number


class Recorder:
    """Takes decision cycles from local clients and writes them under ``root``."""

    def __init__(
        self,
        root: str | Path,
        *,
        socket_path: str | Path | None = None,
        tcp: tuple[str, int] | None = None,
        config: LoggerConfig | None = None,
        max_frame_bytes: int = MAX_FRAME_BYTES,
        max_connections: int = 256,
    ) -> None:
        if socket_path is None and tcp is None:
            raise UsageError("give a socket path, a TCP address, or both")
        self.root = Path(root)
        self.socket_path = None if socket_path is None else Path(socket_path)
        self.tcp = tcp
        self.max_frame_bytes = max_frame_bytes
        self.max_connections = max_connections
        self.counters = RecorderCounters()
        self._config = config or LoggerConfig()
        self._stopping = threading.Event()
        self._listeners: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self.robots = Robots(self.root, self._config)

    # --- life cycle ---------------------------------------------------------------------

    def open(self) -> list[str]:
        """Create the root and the listening sockets; return what it listens on."""
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise StorageError(str(self.root), err.strerror or str(err)) from err
        where = []
        if self.socket_path is not None:
            self._listeners.append(_listen_unix(self.socket_path))
            where.append(f"unix:{self.socket_path}")
        if self.tcp is not None:
            listener = _listen_tcp(self.tcp)
            self._listeners.append(listener)
            host, port = listener.getsockname()[:2]
            self.tcp = (host, port)
            where.append(f"tcp:{host}:{port}")
        return where

    def serve(self) -> None:
        """Accept clients until ``stop()``; each gets its own thread."""
        with selectors.DefaultSelector() as selector:
            for listener in self._listeners:
                selector.register(listener, selectors.EVENT_READ)
            while not self._stopping.is_set():
                for key, _ in selector.select(_POLL_S):
                    assert isinstance(key.fileobj, socket.socket)
                    self._accept(key.fileobj)
                self._threads = [t for t in self._threads if t.is_alive()]

    def stop(self) -> None:
        """Ask ``serve`` and every connection to end (safe from a signal handler)."""
        self._stopping.set()

    def close(self) -> None:
        """Stop, let every connection close its robot's logger (queues written, segments
        finished), and remove the socket file."""
        self.stop()
        for thread in self._threads:
            thread.join(_JOIN_S)
        for listener in self._listeners:
            listener.close()
        self._listeners.clear()
        if self.socket_path is not None:
            try:
                if stat.S_ISSOCK(self.socket_path.lstat().st_mode):
                    self.socket_path.unlink()
            except FileNotFoundError:
                pass

    def __enter__(self) -> Recorder:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- clients ------------------------------------------------------------------------

    def _accept(self, listener: socket.socket) -> None:
        try:
            sock, address = listener.accept()
        except (BlockingIOError, ConnectionAbortedError):
            return
        self.counters.add("connections")
        peer = f"{address[0]}:{address[1]}" if isinstance(address, tuple) else "unix client"
        if len(self._threads) >= self.max_connections:
            self.counters.add("refused_connections")
            log.warning("%s: refused: %d clients already connected", peer, len(self._threads))
            reason = f"the recorder takes at most {self.max_connections} clients"
            try:
                sock.settimeout(1.0)
                sock.sendall(encode_frame({"kind": "refused", "reason": reason}))
            except OSError:
                pass
            sock.close()
            return
        connection = Connection(
            sock,
            peer=peer,
            robots=self.robots,
            counters=self.counters,
            stopping=self._stopping,
            max_frame_bytes=self.max_frame_bytes,
        )
        thread = threading.Thread(target=connection.run, name=f"recorder {peer}", daemon=True)
        thread.start()
        self._threads.append(thread)


def _listen_unix(path: Path) -> socket.socket:
    """Bind the socket file with mode 0660 from its first moment (the umask is set around
    the bind, so no other user can connect in between); a stale file from a killed
    recorder is replaced, a live recorder's is not."""
    if path.exists() or path.is_symlink():
        _remove_stale(path)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    previous = os.umask(0o777 & ~SOCKET_MODE)
    try:
        sock.bind(str(path))
        os.chmod(path, SOCKET_MODE)
    except OSError as err:
        sock.close()
        raise StorageError(str(path), err.strerror or str(err)) from err
    finally:
        os.umask(previous)
    sock.listen(64)
    sock.setblocking(False)
    return sock


def _remove_stale(path: Path) -> None:
    if not stat.S_ISSOCK(path.lstat().st_mode):
        raise StorageError(str(path), "exists and is not a socket")
    probe = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        probe.connect(str(path))
    except OSError as err:
        if err.errno not in (errno.ECONNREFUSED, errno.ENOENT):
            raise StorageError(str(path), err.strerror or str(err)) from err
        path.unlink(missing_ok=True)
        return
    finally:
        probe.close()
    raise UsageError(f"{path}: another recorder is listening on this socket")


def _listen_tcp(address: tuple[str, int]) -> socket.socket:
    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
    except OSError as err:
        sock.close()
        raise StorageError(f"{address[0]}:{address[1]}", err.strerror or str(err)) from err
    sock.listen(64)
    sock.setblocking(False)
    return sock
