"""``trace-audit witness serve``: a C2SP tlog-witness (c2sp.org/tlog-witness) for robot logs.

``POST /add-checkpoint`` checks, in order:

1. the body's form (``witness_client.parse_add_checkpoint``) -> 400;
2. the note's origin is a log this witness was given (``--log VKEY``) -> else 404;
3. the note verifies under that log's key -> else 403; its text is a checkpoint -> else 400;
4. the old size is at most the checkpoint's -> else 400;
5. the old size is the size it last cosigned for the origin (0 when none) -> else 409 with
   that size (``text/x.tlog.size``); a checkpoint of the same size must have the same root
   -> else 409;
6. the consistency proof from its stored tree to the new one verifies -> else 422;

then stores the checkpoint (SQLite, synchronous FULL) before it answers 200 with its
tlog-cosignature/v1 line, timestamped with its own clock. ``GET /checkpoint/<origin>`` (our
extension) answers the latest cosigned note for an origin (404 when none). Given a folder
``publish`` writes (``--tiles``), ``GET /tiles/<robot>/...`` serves it read-only (``tiles``).
"""

from __future__ import annotations

import signal
import sys
import threading
import time
import urllib.parse
from collections.abc import Iterable
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from types import FrameType

from trace_audit.witness.state import Latest, WitnessState
from trace_audit.witness.tiles import PREFIX, TileFolder
from trace_runtime.errors import (
    NoteError,
    StorageError,
    UnverifiedNoteError,
    UsageError,
    WitnessProtocolError,
)
from trace_runtime.tlog.merkle import EMPTY_ROOT, verify_consistency
from trace_runtime.tlog.signed_note import (
    COSIGNATURE,
    ED25519,
    NoteSigner,
    NoteVerifier,
    cosignature_line,
    open_note,
    parse_checkpoint,
    parse_verifier_key,
)
from trace_runtime.tlog.signers import open_signer
from trace_runtime.tlog.witness_client import (
    CONTENT_TYPE_SIZE,
    MAX_BODY_BYTES,
    parse_add_checkpoint,
)

__all__ = ["DEFAULT_NAME", "Answer", "Witness", "parse_listen", "serve"]

DEFAULT_NAME = "trace.local/witness"
_TEXT = "text/plain; charset=utf-8"
_COSIGNATURE_TYPE = "text/x.tlog.cosignature"


@dataclass(frozen=True, slots=True)
class Answer:
    status: int
    body: bytes
    content_type: str = _TEXT
    cache_control: str = ""


def _text(status: int, message: str) -> Answer:
    return Answer(status, (message + "\n").encode())


class Witness:
    """The witness's rules, apart from HTTP (see the module doc)."""

    def __init__(
        self,
        cosigner: NoteSigner,
        logs: Iterable[NoteVerifier],
        state: WitnessState,
    ) -> None:
        if cosigner.sig_type != COSIGNATURE:
            raise UsageError("a witness cosigns with a COSIGNATURE key")
        self.cosigner = cosigner
        # Several keys of one origin: a robot rotating its key (profile 1.5) signs with the
        # old one up to the announcing checkpoint and with the new one after it.
        self.logs: dict[str, list[NoteVerifier]] = {}
        for v in logs:
            if v.sig_type != ED25519:
                raise UsageError(f"log key {v.name} is not an Ed25519 note key")
            self.logs.setdefault(v.name, []).append(v)
        self.state = state

    def add_checkpoint(self, body: bytes) -> Answer:
        try:
            request = parse_add_checkpoint(body)
        except WitnessProtocolError as err:
            return _text(400, str(err))
        origin = request.note.split(b"\n", 1)[0].decode("utf-8", "replace")
        verifiers = self.logs.get(origin)
        if verifiers is None:
            return _text(404, f"unknown origin {origin[:100]!r}")
        try:
            opened = open_note(request.note, verifiers)
        except (UnverifiedNoteError, NoteError) as err:
            return _text(403, f"the note does not verify under {origin}'s key: {err}")
        try:
            checkpoint = parse_checkpoint(opened.text)
        except NoteError as err:
            return _text(400, f"not a checkpoint: {err}")
        if checkpoint.origin != origin:  # not reachable: the first line is the origin
            return _text(400, "the checkpoint's origin is not its first line")
        if request.old_size > checkpoint.size:
            return _text(400, f"old size {request.old_size} is above the checkpoint's size")
        with self.state.locked() as state:
            latest = state.latest(origin)
            size, root = (latest.tree_size, latest.root) if latest else (0, EMPTY_ROOT)
            if request.old_size != size:
                return Answer(409, f"{size}\n".encode(), CONTENT_TYPE_SIZE)
            if checkpoint.size == size and latest is not None and checkpoint.root != root:
                return Answer(409, f"{size}\n".encode(), CONTENT_TYPE_SIZE)
            if checkpoint.size > size and not verify_consistency(
                size, checkpoint.size, root, checkpoint.root, request.proof
            ):
                return _text(422, f"the consistency proof from size {size} does not verify")
            if checkpoint.size == size and request.proof:
                return _text(422, "a proof between equal sizes is empty")
            stamp = int(time.time())
            if latest is not None and stamp < latest.timestamp:
                stamp = latest.timestamp  # never earlier than what it already vouched for
            line = cosignature_line(opened.text, self.cosigner, stamp)
            note = request.note.decode() + line
            state.store(Latest(origin, checkpoint.size, checkpoint.root, note, stamp))
        return Answer(200, line.encode(), _COSIGNATURE_TYPE)

    def checkpoint(self, origin: str) -> Answer:
        latest = self.state.latest(origin)
        if latest is None:
            return _text(404, f"no checkpoint cosigned for {origin[:100]!r}")
        return Answer(200, latest.note.encode(), _TEXT)


def _tile_answer(tiles: TileFolder | None, path: str) -> Answer:
    served = tiles.get(path[len(PREFIX) :]) if tiles is not None else None
    if served is None:
        return _text(404, "not found")
    return Answer(200, served.body, served.content_type, served.cache_control)


def _handler(witness: Witness, tiles: TileFolder | None) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        server_version = "trace-witness/1"
        protocol_version = "HTTP/1.1"
        timeout = 10  # seconds a connection may stall: a slow client does not hold a thread

        def _send(self, answer: Answer) -> None:
            self.send_response(answer.status)
            self.send_header("Content-Type", answer.content_type)
            self.send_header("Content-Length", str(len(answer.body)))
            if answer.cache_control:
                self.send_header("Cache-Control", answer.cache_control)
            self.end_headers()
            self.wfile.write(answer.body)

        def do_POST(self) -> None:
            if self.path != "/add-checkpoint":
                self.close_connection = True
                self._send(_text(404, "not found"))
                return
            length_text = self.headers.get("Content-Length", "")
            if not length_text.isdigit():
                self.close_connection = True
                self._send(_text(411, "a Content-Length is needed"))
                return
            length = int(length_text)
            if length > MAX_BODY_BYTES:
                self.close_connection = True
                self._send(_text(413, f"a request over {MAX_BODY_BYTES} bytes"))
                return
            body = self.rfile.read(length)
            self._send(witness.add_checkpoint(body))

        def do_GET(self) -> None:
            if self.path.startswith(PREFIX):
                self._send(_tile_answer(tiles, self.path))
                return
            prefix = "/checkpoint/"
            if not self.path.startswith(prefix):
                self._send(_text(404, "not found"))
                return
            self._send(witness.checkpoint(urllib.parse.unquote(self.path[len(prefix) :])))

        def log_message(self, format: str, *args: object) -> None:
            line = format % args
            sys.stderr.write(f"witness: {self.address_string()} {' '.join(line.split())}\n")

    return Handler


def parse_listen(listen: str) -> tuple[str, int]:
    host, sep, port = listen.rpartition(":")
    if not sep or not port.isdigit() or int(port) > 65535:
        raise UsageError(f"--listen takes HOST:PORT, got {listen!r}")
    return host.strip("[]") or "127.0.0.1", int(port)


def serve(
    listen: str,
    state_dir: Path,
    key: str | Path,
    logs: Iterable[str],
    *,
    name: str = DEFAULT_NAME,
    tiles: Path | None = None,
) -> int:
    """Run the witness (and serve ``tiles``) until SIGINT/SIGTERM (exit 0); prints its key."""
    host, port = parse_listen(listen)
    folder = TileFolder(tiles) if tiles is not None else None
    try:
        verifiers = [parse_verifier_key(v) for v in logs]
    except NoteError as err:
        raise UsageError(f"--log: {err}") from err
    if not verifiers:
        raise UsageError("a witness needs at least one --log key")
    signer = open_signer(key)
    try:
        cosigner = NoteSigner(name, signer, signer.public_key.raw, COSIGNATURE)
    except NoteError as err:
        raise UsageError(f"--name: {err}") from err
    # Listen before the state is made: a witness that cannot start (its port taken) leaves
    # no witness.sqlite behind in a folder it may just have created.
    try:
        httpd = ThreadingHTTPServer((host, port), BaseHTTPRequestHandler)
    except OSError as err:
        raise UsageError(f"cannot listen on {listen}: {err.strerror or err}") from err
    try:
        state = WitnessState(state_dir)
    except StorageError:
        httpd.server_close()
        raise
    httpd.RequestHandlerClass = _handler(Witness(cosigner, verifiers, state), folder)
    httpd.daemon_threads = True
    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        stop.set()
        threading.Thread(target=httpd.shutdown, daemon=True).start()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    bound_host, bound_port = str(httpd.server_address[0]), int(httpd.server_address[1])
    also = f", serving the tiles of {tiles} at {PREFIX}" if tiles is not None else ""
    sys.stderr.write(
        f"witness: listening on http://{bound_host}:{bound_port} as {cosigner.vkey} "
        f"for {len(verifiers)} log(s){also}\n"
    )
    sys.stderr.flush()
    try:
        httpd.serve_forever(poll_interval=0.2)
    finally:
        httpd.server_close()
        state.close()
    sys.stderr.write("witness: stopped\n")
    return 0
