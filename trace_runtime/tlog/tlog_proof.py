"""C2SP tlog-proof (c2sp.org/tlog-proof@v1): an entry's inclusion in a log, offline-checkable.

The text is lines separated by newlines: ``c2sp.org/tlog-proof@v1``; optionally ``extra
<base64>`` (opaque, unauthenticated); ``index <N>`` (decimal, no leading zero); zero or more
base64 SHA-256 hashes, the RFC 6962 inclusion proof from the leaf's sibling up to the
root's child; an empty line; then the checkpoint note verbatim (c2sp.org/tlog-checkpoint,
with its signatures). This module writes and parses the text, strictly (one spelling per
proof); checking the hashes and the note is the caller's (``merkle``, ``signed_note``).
"""

from __future__ import annotations

import base64
import binascii
from collections.abc import Sequence
from dataclasses import dataclass

from trace_runtime.errors import NoteError
from trace_runtime.tlog.merkle import HASH_SIZE

__all__ = ["TLOG_PROOF_HEADER", "TlogProof", "format_tlog_proof", "parse_tlog_proof"]

TLOG_PROOF_HEADER = "c2sp.org/tlog-proof@v1"


@dataclass(frozen=True, slots=True)
class TlogProof:
    """A parsed tlog-proof: the entry's index, its inclusion proof, the checkpoint note as
    it was embedded, and the extra data (None when there is no extra line)."""

    index: int
    hashes: tuple[bytes, ...]
    note: str
    extra: bytes | None = None


def format_tlog_proof(
    index: int, hashes: Sequence[bytes], note: str, extra: bytes | None = None
) -> str:
    """The tlog-proof text of leaf ``index`` with its inclusion proof and checkpoint note."""
    if isinstance(index, bool) or not isinstance(index, int) or index < 0:
        raise NoteError(f"a tlog-proof's index is a non-negative integer, got {index!r}")
    if any(len(h) != HASH_SIZE for h in hashes):
        raise NoteError("a tlog-proof's hashes are 32-byte SHA-256 digests")
    lines = [TLOG_PROOF_HEADER]
    if extra is not None:
        lines.append(f"extra {base64.b64encode(extra).decode()}")
    lines.append(f"index {index}")
    lines += [base64.b64encode(h).decode() for h in hashes]
    return "\n".join(lines) + "\n\n" + note


def _b64(text: str, what: str) -> bytes:
    """Canonical standard base64 only: a second spelling of the same bytes is refused."""
    try:
        data = base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError) as err:
        raise NoteError(f"a tlog-proof's {what} is not base64") from err
    if base64.b64encode(data).decode() != text:
        raise NoteError(f"a tlog-proof's {what} is not canonical base64")
    return data


def parse_tlog_proof(text: str) -> TlogProof:
    """Parse a tlog-proof text; ``NoteError`` with one line when it is off the spec."""
    head, blank, note = text.partition("\n\n")
    if not blank:
        raise NoteError("a tlog-proof has an empty line before its checkpoint")
    lines = head.split("\n")
    if lines[0] != TLOG_PROOF_HEADER:
        raise NoteError(f"a tlog-proof starts with the line {TLOG_PROOF_HEADER}")
    rest = lines[1:]
    extra = None
    if rest and rest[0].startswith("extra "):
        extra = _b64(rest.pop(0).removeprefix("extra "), "extra data")
    if not rest or not rest[0].startswith("index "):
        raise NoteError("a tlog-proof names its entry's index on the line after its header")
    digits = rest.pop(0).removeprefix("index ")
    if not digits.isascii() or not digits.isdigit() or (digits != "0" and digits[0] == "0"):
        raise NoteError(f"a tlog-proof's index is a decimal with no leading zero, got {digits!r}")
    hashes = tuple(_b64(line, "hash") for line in rest)
    if any(len(h) != HASH_SIZE for h in hashes):
        raise NoteError("a tlog-proof's hashes are 32-byte SHA-256 digests")
    return TlogProof(int(digits), hashes, note, extra)
