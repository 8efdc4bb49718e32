"""Ed25519 keys for checkpoint signatures: the ``Signer`` a logger signs with (a key file,
or an HSM behind the protocol), the ``PublicKey`` an investigator checks with, and the key
files (``NAME.key`` PKCS#8 PEM, mode 0600; ``NAME.pub``) that ``generate_keypair`` writes.

``cryptography`` is imported only when a key is used, so a robot logging unsigned
checkpoints does not pay for it. The formats are specified in docs/integrity.md.
"""

from __future__ import annotations

import errno
import hashlib
import logging
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, runtime_checkable

from trace_runtime.errors import StorageError, UsageError
from trace_runtime.tlog.pkcs11_uri import is_token_uri

if TYPE_CHECKING:
    from cryptography.hazmat.primitives.asymmetric.ed25519 import (
        Ed25519PrivateKey,
    )


__all__ = [
    "PRIVATE_SUFFIX",
    "PUBLIC_SUFFIX",
    "Ed25519Signer",
    "KeyPair",
    "PublicKey",
    "Signer",
    "generate_keypair",
    "key_id_of",
    "load_public_key",
    "load_signer",
    "public_pem_of",
]

log = logging.getLogger("trace_runtime")

PRIVATE_SUFFIX = ".key"
PUBLIC_SUFFIX = ".pub"


def key_id_of(raw_public_key: bytes) -> str:
    """The key id of an Ed25519 public key: SHA-256 hex of its raw 32 bytes."""
    return hashlib.sha256(raw_public_key).hexdigest()


@runtime_checkable
class Signer(Protocol):
    """What the logger needs to sign checkpoints; an HSM or TPM can stand behind it."""

    @property
    def key_id(self) -> str: ...

    def sign(self, data: bytes) -> bytes: ...


@dataclass(frozen=True, slots=True)
class PublicKey:
    """An Ed25519 public key that checks checkpoint signatures."""

    raw: bytes
    key_id: str

    @classmethod
    def from_raw(cls, raw: bytes) -> PublicKey:
        if len(raw) != 32:
            raise UsageError(f"an Ed25519 public key is 32 bytes, got {len(raw)}")
        return cls(raw, key_id_of(raw))

    def verify(self, signature: bytes, data: bytes) -> bool:
        """True when ``signature`` is this key's Ed25519 signature of ``data``."""
        from cryptography.exceptions import InvalidSignature
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

        try:
            Ed25519PublicKey.from_public_bytes(self.raw).verify(signature, data)
        except (InvalidSignature, ValueError):
            return False
        return True


class Ed25519Signer:
    """Signs with an Ed25519 private key held in memory."""

    __slots__ = ("_key", "key_id", "public_key")

    def __init__(self, key: Ed25519PrivateKey) -> None:
        from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

        self._key = key
        raw = key.public_key().public_bytes(Encoding.Raw, PublicFormat.Raw)
        self.public_key = PublicKey.from_raw(raw)
        self.key_id = self.public_key.key_id

    @classmethod
    def generate(cls) -> Ed25519Signer:
        """A signer with a fresh random key (tests, or a key the caller stores itself)."""
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

        return cls(Ed25519PrivateKey.generate())

    def sign(self, data: bytes) -> bytes:
        return self._key.sign(data)

    def private_pem(self) -> bytes:
        """The private key as unencrypted PKCS#8 PEM (what ``keygen`` writes)."""
        from cryptography.hazmat.primitives.serialization import (
            Encoding,
            NoEncryption,
            PrivateFormat,
        )

        return self._key.private_bytes(Encoding.PEM, PrivateFormat.PKCS8, NoEncryption())

    def public_pem(self) -> bytes:
        """The public key as SubjectPublicKeyInfo PEM."""
        from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

        return self._key.public_key().public_bytes(Encoding.PEM, PublicFormat.SubjectPublicKeyInfo)


def public_pem_of(raw: bytes) -> bytes:
    """A raw Ed25519 public key as SubjectPublicKeyInfo PEM (what ``keygen`` writes)."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

    key = Ed25519PublicKey.from_public_bytes(PublicKey.from_raw(raw).raw)
    return key.public_bytes(Encoding.PEM, PublicFormat.SubjectPublicKeyInfo)


def _read_key_file(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError as err:
        raise UsageError(f"{what} {path}: no such file") from err
    except OSError as err:
        raise UsageError(f"{what} {path}: cannot read ({err.strerror or err})") from err


def load_signer(path: str | Path) -> Ed25519Signer:
    """Load an Ed25519 private key file: PKCS#8 PEM (``keygen``, ``openssl genpkey``) or 32
    raw bytes. A key argument that may also name a key in a token: ``signers.open_signer``."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
    from cryptography.hazmat.primitives.serialization import load_pem_private_key

    path = Path(path)
    data = _read_key_file(path, "private key")
    try:
        mode = path.stat().st_mode
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            log.warning("private key %s is readable by others (mode %o)", path, mode & 0o777)
    except OSError:
        pass
    if len(data) == 32 and not data.startswith(b"-----"):
        return Ed25519Signer(Ed25519PrivateKey.from_private_bytes(data))
    try:
        key = load_pem_private_key(data, password=None)
    except (ValueError, TypeError) as err:
        raise UsageError(f"private key {path}: not an unencrypted PEM or raw Ed25519 key") from err
    if not isinstance(key, Ed25519PrivateKey):
        raise UsageError(f"private key {path}: not an Ed25519 key")
    return Ed25519Signer(key)


def load_public_key(path: str | Path) -> PublicKey:
    """Load an Ed25519 public key: PEM (SubjectPublicKeyInfo), OpenSSH, or 32 raw bytes; or
    read it from a token, given a ``pkcs11:`` URI (``token.read_token_public_key``)."""
    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    from cryptography.hazmat.primitives.serialization import (
        Encoding,
        PublicFormat,
        load_pem_public_key,
        load_ssh_public_key,
    )

    # A CLI option typed as a path hands a URI over as a Path: its text is the URI.
    if is_token_uri(str(path)):
        # Deferred: python-pkcs11 is loaded only when a URI is used.
        from trace_runtime.tlog.pkcs11_session import read_public_raw
        from trace_runtime.tlog.pkcs11_uri import parse_token_uri

        return PublicKey.from_raw(read_public_raw(parse_token_uri(str(path))))
    path = Path(path)
    data = _read_key_file(path, "public key")
    if len(data) == 32 and not data.startswith((b"-----", b"ssh-")):
        return PublicKey.from_raw(data)
    if b"PRIVATE KEY" in data:
        raise UsageError(f"{path} is a private key; verify with the public key (.pub)")
    try:
        key: object = (
            load_ssh_public_key(data) if data.startswith(b"ssh-") else load_pem_public_key(data)
        )
    except (ValueError, TypeError) as err:
        raise UsageError(f"public key {path}: not a PEM, OpenSSH or raw Ed25519 key") from err
    if not isinstance(key, Ed25519PublicKey):
        raise UsageError(f"public key {path}: not an Ed25519 key")
    return PublicKey.from_raw(key.public_bytes(Encoding.Raw, PublicFormat.Raw))


@dataclass(frozen=True, slots=True)
class KeyPair:
    """Where ``generate_keypair`` wrote a key pair, and its key id."""

    private_path: Path
    public_path: Path
    key_id: str


def generate_keypair(
    directory: str | Path, *, name: str = "trace-ed25519", overwrite: bool = False
) -> KeyPair:
    """Write ``NAME.key`` (PKCS#8 PEM, mode 0600) and ``NAME.pub`` (PEM) into ``directory``.

    A key that exists, a folder that refuses the write, a full disk: ``StorageError`` (the
    CLI's cannot-write), and no half pair is left behind."""
    if not name or "/" in name or name.startswith("."):
        raise UsageError(f"key name must be a plain file name: {name!r}")
    directory = Path(directory)
    private_path = directory / f"{name}{PRIVATE_SUFFIX}"
    public_path = directory / f"{name}{PUBLIC_SUFFIX}"
    if not overwrite:
        for path in (private_path, public_path):
            if path.exists():
                raise StorageError(str(path), "a key exists; refusing to overwrite it (--force)")
    signer = Ed25519Signer.generate()
    try:
        directory.mkdir(parents=True, exist_ok=True)
        _write_private(private_path, signer.private_pem(), overwrite=overwrite)
    except OSError as err:
        raise StorageError(str(directory), err.strerror or str(err)) from err
    try:
        public_path.write_bytes(signer.public_pem())
    except OSError as err:
        # A private key without its public half verifies nothing: take back what we made.
        private_path.unlink(missing_ok=True)
        raise StorageError(str(public_path), err.strerror or str(err)) from err
    return KeyPair(private_path, public_path, signer.key_id)


def _write_private(path: Path, data: bytes, *, overwrite: bool) -> None:
    flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if overwrite else os.O_EXCL)
    fd = os.open(path, flags, 0o600)
    try:
        os.fchmod(fd, 0o600)  # also when overwriting a file that had a looser mode
        if os.write(fd, data) != len(data):
            raise OSError(errno.ENOSPC, "short write")
        os.fsync(fd)
    except OSError:
        if not overwrite:  # O_EXCL made it ours: a torn key file is no key
            path.unlink(missing_ok=True)
        raise
    finally:
        os.close(fd)
