"""C2SP signed notes, tlog checkpoints and tlog cosignatures (Ed25519 only).

- signed-note (c2sp.org/signed-note): a UTF-8 text ending in a newline, a blank line, then
  signature lines ``— <key name> <base64(key id || signature)>``. A key id is the first four
  bytes of ``SHA-256(name || 0x0A || type || public key)``; type 0x01 is a plain Ed25519
  signature of the text. A verifier key is spelled ``<name>+<8 hex key id>+<base64(type ||
  public key)>``.
- tlog-checkpoint (c2sp.org/tlog-checkpoint): the note text ``origin\\nsize\\nbase64(root)\\n``
  and optional non-empty extension lines.
- tlog-cosignature/v1 (c2sp.org/tlog-cosignature): type 0x04, a witness's Ed25519 signature
  of ``cosignature/v1\\ntime <T>\\n`` followed by the checkpoint text; the signature line
  carries ``key id || T (8 bytes, big-endian) || signature``.

Everything a note is made of is checked here; a malformed note is a ``NoteError`` with a
one-line message, and a note no known key verifies is an ``UnverifiedNoteError``.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import string
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from trace_runtime.errors import NoteError, UnverifiedNoteError
from trace_runtime.tlog.keys import PublicKey, Signer

__all__ = [
    "COSIGNATURE",
    "ED25519",
    "MAX_NOTE_BYTES",
    "MAX_SIGNATURES",
    "Checkpoint",
    "NoteSignature",
    "NoteSigner",
    "NoteVerifier",
    "OpenedNote",
    "cosignature_line",
    "cosignature_message",
    "format_checkpoint",
    "key_id",
    "open_note",
    "parse_checkpoint",
    "parse_verifier_key",
    "sign_note",
    "verifier_key",
    "verify_cosignature",
]

ED25519 = 0x01
"""Signature type of a plain Ed25519 note signature (signed-note)."""
COSIGNATURE = 0x04
"""Signature type of a timestamped Ed25519 cosignature (tlog-cosignature/v1)."""

MAX_NOTE_BYTES = 1 << 20
MAX_SIGNATURES = 100

_DASH = "\u2014 "
_COSIG_HEADER = b"cosignature/v1\n"
_MAX_TIMESTAMP = (1 << 63) - 1
_MAX_SIZE = (1 << 63) - 1
_HEX = frozenset(string.hexdigits)
_DIGITS = frozenset(string.digits)
_SIG_LENGTH = {ED25519: 64, COSIGNATURE: 8 + 64}


def _check_name(name: object) -> str:
    """A key name: non-empty, no Unicode space, no plus, no control character."""
    if not isinstance(name, str) or not name:
        raise NoteError("a key name must be a non-empty string")
    for ch in name:
        if ch.isspace() or ch == "+" or ord(ch) < 0x20 or 0xD800 <= ord(ch) <= 0xDFFF:
            raise NoteError(f"key name {name!r} holds a space, plus or control character")
    return name


def key_id(name: str, sig_type: int, public_key_raw: bytes) -> int:
    """The 32-bit key id: SHA-256(name || 0x0A || type || public key)[:4], big-endian."""
    data = name.encode() + b"\n" + bytes([sig_type]) + public_key_raw
    return int.from_bytes(hashlib.sha256(data).digest()[:4], "big")


def verifier_key(name: str, public_key_raw: bytes, sig_type: int = ED25519) -> str:
    """The verifier key string ``<name>+<8 hex key id>+<base64(type || public key)>``."""
    return NoteVerifier.of(name, public_key_raw, sig_type).vkey


def _b64decode(text: str) -> bytes:
    """Standard base64 with padding (RFC 4648 section 4), nothing outside its alphabet, in
    its one canonical spelling: "AB==" (unused bits set) or "AAAA====" (padding beyond the
    data) would let one signature be written two ways, and a witness count it twice."""
    try:
        raw = base64.b64decode(text.encode("ascii"), validate=True)
    except (binascii.Error, UnicodeEncodeError, ValueError) as err:
        raise NoteError("not standard base64") from err
    if base64.b64encode(raw).decode() != text:
        raise NoteError("not canonical base64")
    return raw


def _cosignature_prefix(timestamp: int) -> bytes:
    return _COSIG_HEADER + b"time %d\n" % timestamp


def cosignature_message(checkpoint_body: str, timestamp: int) -> bytes:
    """The bytes a tlog-cosignature/v1 signs: ``cosignature/v1\\ntime <T>\\n`` + the body."""
    _check_timestamp(timestamp)
    return _cosignature_prefix(timestamp) + checkpoint_body.encode()


def _check_timestamp(timestamp: object) -> int:
    if (
        isinstance(timestamp, bool)
        or not isinstance(timestamp, int)
        or not 0 <= timestamp <= _MAX_TIMESTAMP
    ):
        raise NoteError(
            f"a cosignature's timestamp is an integer in [0, 2^63-1], got {timestamp!r}"
        )
    return timestamp


@dataclass(frozen=True, slots=True)
class NoteVerifier:
    """A known key: its name, type (``ED25519`` or ``COSIGNATURE``) and public key."""

    name: str
    sig_type: int
    public_key: PublicKey
    key_id: int

    @classmethod
    def of(cls, name: str, public_key_raw: bytes, sig_type: int = ED25519) -> NoteVerifier:
        _check_name(name)
        if sig_type not in _SIG_LENGTH:
            raise NoteError(f"unsupported signature type 0x{sig_type:02x}")
        if not isinstance(public_key_raw, bytes) or len(public_key_raw) != 32:
            raise NoteError("an Ed25519 public key is 32 bytes")
        return cls(
            name,
            sig_type,
            PublicKey.from_raw(public_key_raw),
            key_id(name, sig_type, public_key_raw),
        )

    @property
    def vkey(self) -> str:
        material = base64.b64encode(bytes([self.sig_type]) + self.public_key.raw).decode()
        return f"{self.name}+{self.key_id:08x}+{material}"

    def check(self, text: bytes, signature: bytes) -> int | None:
        """Verify ``signature`` (without its key id) of the note ``text``; raises NoteError
        when it does not verify. Returns the cosignature's timestamp (None for ED25519)."""
        if len(signature) != _SIG_LENGTH[self.sig_type]:
            raise NoteError(f"signature by {self.name} has the wrong length")
        if self.sig_type == ED25519:
            if not self.public_key.verify(signature, text):
                raise NoteError(f"signature by {self.name} does not verify")
            return None
        timestamp = int.from_bytes(signature[:8], "big")
        if timestamp > _MAX_TIMESTAMP:
            raise NoteError(f"cosignature by {self.name} has a timestamp above 2^63-1")
        if not self.public_key.verify(signature[8:], _cosignature_prefix(timestamp) + text):
            raise NoteError(f"cosignature by {self.name} does not verify")
        return timestamp


def parse_verifier_key(vkey: str) -> NoteVerifier:
    """A verifier key string (``name+hash+base64``) as a ``NoteVerifier``; checks its hash."""
    if not isinstance(vkey, str):
        raise NoteError("a verifier key is a string")
    name, _, rest = vkey.partition("+")
    hash16, _, material64 = rest.partition("+")
    if len(hash16) != 8 or not _HEX.issuperset(hash16):
        raise NoteError("malformed verifier key: the key id is not 8 hex digits")
    _check_name(name)
    material = _b64decode(material64)
    if len(material) < 1:
        raise NoteError("malformed verifier key: no key material")
    if key_id(name, material[0], material[1:]) != int(hash16, 16):
        raise NoteError("malformed verifier key: the key id does not match the key")
    if material[0] not in _SIG_LENGTH:
        raise NoteError(f"unsupported verifier key type 0x{material[0]:02x}")
    return NoteVerifier.of(name, material[1:], material[0])


@dataclass(frozen=True, slots=True)
class NoteSigner:
    """A name and a ``keys.Signer`` (an Ed25519 key, maybe in an HSM) that sign notes:
    plainly (``ED25519``) or as a witness's cosignature (``COSIGNATURE``)."""

    name: str
    signer: Signer
    public_key_raw: bytes
    sig_type: int = ED25519

    def __post_init__(self) -> None:
        NoteVerifier.of(self.name, self.public_key_raw, self.sig_type)

    @property
    def key_id(self) -> int:
        return key_id(self.name, self.sig_type, self.public_key_raw)

    @property
    def verifier(self) -> NoteVerifier:
        return NoteVerifier.of(self.name, self.public_key_raw, self.sig_type)

    @property
    def vkey(self) -> str:
        return self.verifier.vkey

    def signature_line(self, text: str, *, timestamp: int | None = None) -> str:
        """The signature line (ending in a newline) of this key over the note ``text``;
        a cosigner needs the ``timestamp`` (POSIX seconds) it states."""
        data = _check_text(text)
        head = self.key_id.to_bytes(4, "big")
        if self.sig_type == COSIGNATURE:
            if timestamp is None:
                raise NoteError("a cosignature needs a timestamp")
            stamp = _check_timestamp(timestamp)
            sig = self.signer.sign(_cosignature_prefix(stamp) + data)
            raw = head + stamp.to_bytes(8, "big") + sig
        else:
            if timestamp is not None:
                raise NoteError("a plain Ed25519 note signature has no timestamp")
            raw = head + self.signer.sign(data)
        if len(raw) != 4 + _SIG_LENGTH[self.sig_type]:
            raise NoteError(f"signer {self.name} did not make a 64-byte Ed25519 signature")
        return f"{_DASH}{self.name} {base64.b64encode(raw).decode()}\n"


def _check_text(text: object) -> bytes:
    """A note text as bytes: valid UTF-8, ending in a newline, no other control character."""
    if not isinstance(text, str) or not text.endswith("\n"):
        raise NoteError("a note's text must be a string ending in a newline")
    try:
        data = text.encode()
    except UnicodeEncodeError as err:
        raise NoteError("a note's text is not valid UTF-8") from err
    _check_controls(data)
    return data


def _check_controls(data: bytes) -> None:
    if any(b < 0x20 and b != 0x0A for b in data):  # UTF-8 continuation bytes are >= 0x80
        raise NoteError("a note holds an ASCII control character other than newline")


def sign_note(
    text: str, signers: NoteSigner | Sequence[NoteSigner], *, timestamp: int | None = None
) -> str:
    """The signed note: ``text``, a blank line and one signature line per signer."""
    if isinstance(signers, NoteSigner):
        signers = [signers]
    if not signers:
        raise NoteError("a signed note needs at least one signer")
    lines = []
    for s in signers:
        stamp = timestamp if s.sig_type == COSIGNATURE else None
        lines.append(s.signature_line(text, timestamp=stamp))
    return text + "\n" + "".join(lines)


@dataclass(frozen=True, slots=True)
class NoteSignature:
    """One signature line: the key's name and id, and the signature bytes after the id;
    ``timestamp`` is a verified cosignature's time."""

    name: str
    key_id: int
    signature: bytes
    timestamp: int | None = None


@dataclass(frozen=True, slots=True)
class OpenedNote:
    """A note whose known signatures all verified: its text (with the final newline),
    the verified signatures in order, and those by keys not known (ignored, kept)."""

    text: str
    verified: tuple[NoteSignature, ...]
    unverified: tuple[NoteSignature, ...]

    def verified_by(self, verifier: NoteVerifier) -> NoteSignature | None:
        for sig in self.verified:
            if sig.name == verifier.name and sig.key_id == verifier.key_id:
                return sig
        return None


def _note_bytes(note: str | bytes) -> bytes:
    """A note's bytes: text or bytes, at most ``MAX_NOTE_BYTES``, UTF-8, no control
    character but newlines."""
    if isinstance(note, str):
        if len(note) > MAX_NOTE_BYTES:
            raise NoteError(f"a note over {MAX_NOTE_BYTES} bytes is refused")
        try:
            data = note.encode()
        except UnicodeEncodeError as err:
            raise NoteError("a note is not valid UTF-8") from err
    elif isinstance(note, (bytes, bytearray, memoryview)):
        data = bytes(note)
    else:
        raise NoteError("a note is text or bytes")
    if len(data) > MAX_NOTE_BYTES:
        raise NoteError(f"a note over {MAX_NOTE_BYTES} bytes is refused")
    try:
        data.decode()
    except UnicodeDecodeError as err:
        raise NoteError("a note is not valid UTF-8") from err
    _check_controls(data)
    return data


def _known_keys(verifiers: Iterable[NoteVerifier]) -> dict[tuple[str, int], NoteVerifier]:
    """The verifiers by (name, key id); two different keys under one pair are refused."""
    known: dict[tuple[str, int], NoteVerifier] = {}
    for v in verifiers:
        if not isinstance(v, NoteVerifier):
            raise NoteError("verifiers must be NoteVerifier (see parse_verifier_key)")
        if known.setdefault((v.name, v.key_id), v) != v:
            raise NoteError(f"two known keys share the name {v.name} and key id {v.key_id:08x}")
    return known


def open_note(note: str | bytes, verifiers: Iterable[NoteVerifier]) -> OpenedNote:
    """Parse a signed note and verify every signature by a known key.

    Signatures by unknown keys are ignored (kept in ``unverified``); a known key's signature
    that fails is a ``NoteError``; a note no known key signed is an ``UnverifiedNoteError``.
    """
    data = _note_bytes(note)
    known = _known_keys(verifiers)
    split = data.rfind(b"\n\n")
    if split < 0:
        raise NoteError("a note has no blank line before its signatures")
    text, block = data[: split + 1], data[split + 2 :]
    if not block or not block.endswith(b"\n"):
        raise NoteError("a note's signature block is empty or does not end in a newline")
    lines = block[:-1].split(b"\n")
    if len(lines) > MAX_SIGNATURES:
        raise NoteError(f"a note with more than {MAX_SIGNATURES} signatures is refused")
    verified: list[NoteSignature] = []
    unverified: list[NoteSignature] = []
    seen: set[tuple[str, int]] = set()
    seen_lines: set[bytes] = set()
    dash = _DASH.encode()
    for line in lines:
        if not line.startswith(dash):
            raise NoteError("a signature line does not start with an em dash and a space")
        name_b, space, b64 = line[len(dash) :].partition(b" ")
        name = name_b.decode()
        if not space or not b64:
            raise NoteError("a signature line has no signature")
        _check_name(name)
        raw = _b64decode(b64.decode())
        if len(raw) < 5:
            raise NoteError(f"signature by {name} is too short")
        kid = int.from_bytes(raw[:4], "big")
        key = known.get((name, kid))
        if key is None:
            if line not in seen_lines:
                seen_lines.add(line)
                unverified.append(NoteSignature(name, kid, raw[4:]))
            continue
        if (name, kid) in seen:
            continue  # a repeated signature by one key counts once (as in Go's note.Open)
        seen.add((name, kid))
        stamp = key.check(text, raw[4:])
        verified.append(NoteSignature(name, kid, raw[4:], stamp))
    if not verified:
        raise UnverifiedNoteError("no known key signed this note", tuple(unverified))
    return OpenedNote(text.decode(), tuple(verified), tuple(unverified))


@dataclass(frozen=True, slots=True)
class Checkpoint:
    """A tlog checkpoint's body: the log's origin, the tree size, its root hash, and any
    extension lines."""

    origin: str
    size: int
    root: bytes
    extensions: tuple[str, ...] = ()

    def body(self) -> str:
        return format_checkpoint(self.origin, self.size, self.root, self.extensions)


def format_checkpoint(origin: str, size: int, root: bytes, extensions: Sequence[str] = ()) -> str:
    """The checkpoint note text: origin, decimal size, base64 root, extension lines, each
    ending in a newline. The origin follows the spec's SHOULD: no spaces, no plus."""
    _check_name(origin)
    if isinstance(size, bool) or not isinstance(size, int) or not 0 <= size <= _MAX_SIZE:
        raise NoteError(f"a checkpoint's size is an integer in [0, 2^63-1], got {size!r}")
    if not isinstance(root, bytes) or len(root) != 32:
        raise NoteError("a checkpoint's root hash is 32 bytes")
    lines = [origin, str(size), base64.b64encode(root).decode()]
    for ext in extensions:
        if not isinstance(ext, str) or not ext or "\n" in ext:
            raise NoteError("a checkpoint's extension lines are non-empty single lines")
        lines.append(ext)
    text = "\n".join(lines) + "\n"
    _check_text(text)
    return text


def parse_checkpoint(text: str) -> Checkpoint:
    """A checkpoint note text (without signatures) as a ``Checkpoint``, strictly: at least
    three non-empty lines, a decimal size with no leading zero, a canonical base64 root of
    32 bytes. The origin must only be non-empty (the spec tells clients to assume no more)."""
    _check_text(text)
    lines = text[:-1].split("\n")
    if len(lines) < 3:
        raise NoteError("a checkpoint has at least three lines: origin, size, root hash")
    if any(not line for line in lines):
        raise NoteError("a checkpoint has an empty line")
    origin, size_text, root_text = lines[0], lines[1], lines[2]
    if not _DIGITS.issuperset(size_text) or (size_text != "0" and size_text.startswith("0")):
        raise NoteError("a checkpoint's size is a decimal with no leading zero")
    if len(size_text) > 19 or int(size_text) > _MAX_SIZE:
        raise NoteError("a checkpoint's size is beyond 2^63-1")
    root = _b64decode(root_text)
    if len(root) != 32:
        raise NoteError("a checkpoint's root hash is not the base64 of 32 bytes")
    return Checkpoint(origin, int(size_text), root, tuple(lines[3:]))


def cosignature_line(checkpoint_body: str, cosigner: NoteSigner, timestamp: int) -> str:
    """A witness's cosignature line over a checkpoint body (checked to be one)."""
    if cosigner.sig_type != COSIGNATURE:
        raise NoteError("a cosigner's NoteSigner has sig_type COSIGNATURE")
    parse_checkpoint(checkpoint_body)
    return cosigner.signature_line(checkpoint_body, timestamp=timestamp)


def verify_cosignature(checkpoint_body: str, line: str, verifier: NoteVerifier) -> int:
    """Check one cosignature line against a checkpoint body; its timestamp when it verifies,
    a ``NoteError`` otherwise (a line by another key included)."""
    if verifier.sig_type != COSIGNATURE:
        raise NoteError("a cosignature is checked with a COSIGNATURE verifier")
    parse_checkpoint(checkpoint_body)
    if not isinstance(line, str) or line.count("\n") > 1:
        raise NoteError("a cosignature is one signature line")
    line = line if line.endswith("\n") else line + "\n"
    opened = open_note(checkpoint_body + "\n" + line, [verifier])
    stamp = opened.verified[0].timestamp
    if stamp is None:  # not reachable: a COSIGNATURE verifier always reads a timestamp
        raise NoteError("a cosignature without a timestamp")
    return stamp
