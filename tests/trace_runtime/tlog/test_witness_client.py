"""The tlog-witness add-checkpoint body (built and parsed strictly) and the client's outcomes
against a real HTTP server on localhost (a tiny stdlib one answering fixed statuses)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import ClassVar

import pytest

from trace_runtime.errors import WitnessProtocolError
from trace_runtime.tlog.witness_client import (
    MAX_PROOF_HASHES,
    add_checkpoint_body,
    parse_add_checkpoint,
    submit,
)

NOTE = b"trace.local/amr-7\n3\n" + b"A" * 43 + b"=\n\n\xe2\x80\x94 trace.local/amr-7 AAAA\n"
H1, H2 = bytes(range(32)), bytes(32)


def test_a_body_round_trips() -> None:
    body = add_checkpoint_body(2, [H1, H2], NOTE)
    assert body.startswith(b"old 2\n")
    parsed = parse_add_checkpoint(body)
    assert (parsed.old_size, parsed.proof, parsed.note) == (2, (H1, H2), NOTE)
    empty = parse_add_checkpoint(add_checkpoint_body(0, [], NOTE))
    assert (empty.old_size, empty.proof) == (0, ())


@pytest.mark.parametrize(
    "body",
    [
        b"",
        b"old\n\n" + NOTE,
        b"old 01\n\n" + NOTE,
        b"old -1\n\n" + NOTE,
        b"old 99999999999999999999\n\n" + NOTE,
        b"new 1\n\n" + NOTE,
        b"old 1\nnot base64!\n\n" + NOTE,
        b"old 1\nAAAA\n\n" + NOTE,  # 3 bytes, not 32
        b"old 1\n" + NOTE,  # the note's first line read as a proof line
        b"old 1\n\n",
        b"old 1\n\n" + NOTE[:-1],
        b"old 1",
        b"old 1\n"
        + b"AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA=\n" * (MAX_PROOF_HASHES + 1)
        + b"\n"
        + NOTE,
        b"old 1\n\n" + b"x" * (1 << 17) + b"\n",
    ],
)
def test_malformed_bodies_are_one_error(body: bytes) -> None:
    with pytest.raises(WitnessProtocolError) as err:
        parse_add_checkpoint(body)
    assert "\n" not in str(err.value)


def test_the_builder_refuses_what_the_parser_would() -> None:
    for bad in ((-1, [], NOTE), (1, [b"short"], NOTE), (1, [], b"no newline"), (True, [], NOTE)):
        with pytest.raises(WitnessProtocolError):
            add_checkpoint_body(*bad)


class _Fixed(BaseHTTPRequestHandler):
    answers: ClassVar[dict[str, tuple[int, bytes]]] = {
        "/ok/add-checkpoint": (200, "\u2014 w AAAA\n\u2014 w BBBB\n".encode()),
        "/late/add-checkpoint": (409, b"17\n"),
        "/bad/add-checkpoint": (403, b"signature does not verify\n"),
        "/garbage/add-checkpoint": (200, b"hello"),
    }
    seen: ClassVar[list[bytes]] = []

    def do_POST(self) -> None:
        length = int(self.headers.get("Content-Length", "0"))
        self.seen.append(self.rfile.read(length))
        status, body = self.answers.get(self.path, (404, b"unknown origin\n"))
        self.send_response(status)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *_args: object) -> None:
        pass


@pytest.fixture
def server() -> Iterator[str]:
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _Fixed)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


def test_the_client_says_what_the_witness_answered(server: str) -> None:
    ok = submit(server + "/ok", 0, [], NOTE)
    assert ok.ok and ok.cosignatures == ("\u2014 w AAAA\n", "\u2014 w BBBB\n")
    assert _Fixed.seen[-1] == add_checkpoint_body(0, [], NOTE)
    late = submit(server + "/late/", 3, [H1], NOTE)
    assert (late.outcome, late.status, late.witness_size) == ("conflict", 409, 17)
    bad = submit(server + "/bad", 0, [], NOTE)
    assert (bad.outcome, bad.status, bad.detail) == ("refused", 403, "signature does not verify")
    assert submit(server + "/nowhere", 0, [], NOTE).status == 404
    assert submit(server + "/garbage", 0, [], NOTE).outcome == "refused"


def test_the_client_never_raises_for_the_network() -> None:
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    down = submit(f"http://127.0.0.1:{port}", 0, [], NOTE, timeout_s=0.5)
    assert down.outcome == "unreachable" and down.detail
    assert submit("file:///etc/passwd", 0, [], NOTE).outcome == "unreachable"
    assert submit("http://[::1", 0, [], NOTE).outcome == "unreachable"
