"""The C2SP tlog-witness ``add-checkpoint`` call: its request body and an HTTP client.

The body (c2sp.org/tlog-witness) is an ``old <size>`` line, the consistency proof from that
size to the checkpoint's, one base64 hash a line, an empty line, then the signed checkpoint
note. A witness answers 200 with its cosignature line(s), 409 with its own size (the client
asked from a size it does not hold, or the tree is older or different), 403 when the
note's signature does not verify, 404 for an origin it does not know, 422 for a proof that
does not verify and 400 for a malformed request.

``submit`` is what a logger calls from its writer thread: it never raises for a network or
HTTP failure, it says what happened (``Submitted``); a caller retries with its next
checkpoint. Stdlib only (urllib), floor 1.
"""

from __future__ import annotations

import base64
import binascii
import contextlib
import urllib.error
import urllib.request
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from trace_runtime.errors import WitnessProtocolError
from trace_runtime.tlog.merkle import HASH_SIZE
from trace_runtime.tlog.signed_note import MAX_NOTE_BYTES

__all__ = [
    "CONTENT_TYPE_SIZE",
    "MAX_BODY_BYTES",
    "MAX_PROOF_HASHES",
    "AddCheckpoint",
    "Submitted",
    "add_checkpoint_body",
    "parse_add_checkpoint",
    "submit",
]

MAX_PROOF_HASHES = 63
"""A consistency proof of trees below 2^63 leaves has at most 63 hashes (tlog-witness)."""
MAX_BODY_BYTES = 64 << 10
"""The largest request a witness reads: the proof lines and a note with a few signatures."""
_MAX_RESPONSE_BYTES = 64 << 10
_MAX_SIZE = (1 << 63) - 1
CONTENT_TYPE_SIZE = "text/x.tlog.size"
"""The content type of a 409 answer: the witness's size for the origin, a decimal line."""


@dataclass(frozen=True, slots=True)
class AddCheckpoint:
    """A parsed add-checkpoint request: the size the client proves from, the proof, the note."""

    old_size: int
    proof: tuple[bytes, ...]
    note: bytes


def _size(text: str) -> int:
    if not text or not text.isascii() or not text.isdigit() or len(text) > 19:
        raise WitnessProtocolError(f"not a tree size: {text[:40]!r}")
    if text != "0" and text.startswith("0"):
        raise WitnessProtocolError("a tree size has no leading zero")
    value = int(text)
    if value > _MAX_SIZE:
        raise WitnessProtocolError("a tree size is at most 2^63-1")
    return value


def add_checkpoint_body(old_size: int, proof: Sequence[bytes], note: str | bytes) -> bytes:
    """The request body of ``POST /add-checkpoint``."""
    if (
        isinstance(old_size, bool)
        or not isinstance(old_size, int)
        or not 0 <= old_size <= _MAX_SIZE
    ):
        raise WitnessProtocolError(f"old size must be an integer in [0, 2^63-1], got {old_size!r}")
    if len(proof) > MAX_PROOF_HASHES:
        raise WitnessProtocolError(f"a consistency proof has at most {MAX_PROOF_HASHES} hashes")
    if any(not isinstance(h, bytes) or len(h) != HASH_SIZE for h in proof):
        raise WitnessProtocolError("a consistency proof's hashes are 32 bytes each")
    data = note.encode() if isinstance(note, str) else bytes(note)
    if not data.endswith(b"\n"):
        raise WitnessProtocolError("a signed note ends in a newline")
    lines = [f"old {old_size}\n".encode()]
    lines += [base64.b64encode(h) + b"\n" for h in proof]
    body = b"".join(lines) + b"\n" + data
    if len(body) > MAX_BODY_BYTES:
        raise WitnessProtocolError(f"an add-checkpoint request over {MAX_BODY_BYTES} bytes")
    return body


def parse_add_checkpoint(body: bytes) -> AddCheckpoint:
    """An add-checkpoint request body, strictly: ``WitnessProtocolError`` (one line) for
    anything else. The note itself is only split off here; the witness opens it."""
    if not isinstance(body, bytes | bytearray | memoryview):
        raise WitnessProtocolError("a request body is bytes")
    data = bytes(body)
    if len(data) > MAX_BODY_BYTES:
        raise WitnessProtocolError(f"an add-checkpoint request over {MAX_BODY_BYTES} bytes")
    head, sep, rest = data.partition(b"\n")
    if not sep or not head.startswith(b"old "):
        raise WitnessProtocolError("the request does not start with an 'old <size>' line")
    try:
        old_size = _size(head[4:].decode("ascii"))
    except UnicodeDecodeError as err:
        raise WitnessProtocolError("the old size line is not ASCII") from err
    proof: list[bytes] = []
    while True:
        line, sep, rest = rest.partition(b"\n")
        if not sep:
            raise WitnessProtocolError("the request has no empty line before the note")
        if not line:
            break
        if len(proof) == MAX_PROOF_HASHES:
            raise WitnessProtocolError(f"a consistency proof has at most {MAX_PROOF_HASHES} hashes")
        try:
            digest = base64.b64decode(line, validate=True)
        except (binascii.Error, ValueError) as err:
            raise WitnessProtocolError("a proof line is not base64") from err
        if len(digest) != HASH_SIZE or base64.b64encode(digest) != line:
            raise WitnessProtocolError("a proof line is not the base64 of a 32-byte hash")
        proof.append(digest)
    if not rest:
        raise WitnessProtocolError("the request holds no checkpoint note")
    if len(rest) > MAX_NOTE_BYTES or not rest.endswith(b"\n"):
        raise WitnessProtocolError("the checkpoint note does not end in a newline")
    return AddCheckpoint(old_size, tuple(proof), rest)


Outcome = Literal["cosigned", "conflict", "refused", "unreachable"]


@dataclass(frozen=True, slots=True)
class Submitted:
    """What a witness made of a checkpoint.

    - ``cosigned``: 200; ``cosignatures`` holds the signature lines it returned (each
      ending in a newline).
    - ``conflict``: 409; ``witness_size`` is the size the witness holds for the origin
      (None when its body did not say), so the caller can retry with a proof from there.
    - ``refused``: 400/403/404/422 or another status; ``status`` and one-line ``detail``.
    - ``unreachable``: no HTTP answer (refused connection, timeout, a bad URL); ``detail``.
    """

    outcome: Outcome
    status: int | None = None
    cosignatures: tuple[str, ...] = ()
    witness_size: int | None = None
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.outcome == "cosigned"


def _one_line(data: bytes, limit: int = 200) -> str:
    text = data.decode("utf-8", "replace").strip()
    text = " ".join(text.split())
    return text[:limit]


def _cosignature_lines(data: bytes) -> tuple[str, ...] | None:
    try:
        text = data.decode()
    except UnicodeDecodeError:
        return None
    if not text.endswith("\n"):
        return None
    lines = text[:-1].split("\n")
    if not lines or any(not line.startswith("\u2014 ") for line in lines):
        return None
    return tuple(line + "\n" for line in lines)


def submit(
    url: str,
    old_size: int,
    proof: Sequence[bytes],
    note: str | bytes,
    *,
    timeout_s: float = 2.0,
) -> Submitted:
    """POST the checkpoint ``note`` with its consistency ``proof`` from ``old_size`` to
    ``<url>/add-checkpoint``; never raises for a network or HTTP failure (a malformed
    argument is still a ``WitnessProtocolError``)."""
    body = add_checkpoint_body(old_size, proof, note)
    endpoint = url.rstrip("/") + "/add-checkpoint"
    if not endpoint.startswith(("http://", "https://")):
        return Submitted("unreachable", detail=f"not an http(s) URL: {url[:80]}")
    try:
        request = urllib.request.Request(
            endpoint,
            data=body,
            method="POST",
            headers={"Content-Type": "text/plain; charset=utf-8"},
        )
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            status = response.status
            data = response.read(_MAX_RESPONSE_BYTES + 1)
    except urllib.error.HTTPError as err:
        status = err.code
        data = b""
        with contextlib.suppress(OSError):
            data = err.read(_MAX_RESPONSE_BYTES + 1)
        err.close()
        return _answer(status, data)
    except (urllib.error.URLError, OSError, ValueError) as err:
        reason = getattr(err, "reason", err)
        return Submitted("unreachable", detail=_one_line(str(reason).encode()) or "no answer")
    return _answer(status, data)


def _answer(status: int, data: bytes) -> Submitted:
    if len(data) > _MAX_RESPONSE_BYTES:
        return Submitted("refused", status, detail="the witness's answer is over 64 KiB")
    if status == 200:
        lines = _cosignature_lines(data)
        if lines is None:
            return Submitted("refused", status, detail="200 without cosignature lines")
        return Submitted("cosigned", status, cosignatures=lines)
    if status == 409:
        size: int | None = None
        with contextlib.suppress(WitnessProtocolError, UnicodeDecodeError):
            size = _size(data.decode("ascii").strip())
        return Submitted("conflict", status, witness_size=size, detail=_one_line(data))
    return Submitted("refused", status, detail=_one_line(data) or f"HTTP {status}")
