"""Ed25519 keys held in a PKCS#11 token (an HSM, a smart card, a TPM's PKCS#11 face,
SoftHSM2): the ``TokenSigner`` a logger or a witness signs through, and
``generate_token_key``, which makes a key inside the token and writes only its public half,
and ``read_token_public_key`` / ``export_token_public_key``, which read that half back (a
lost ``.pub``, or a verifier on the robot itself).

The private key never leaves the token: it is generated there as a token object that is
sensitive and not extractable, and every signature is the token's own (``CKM_EDDSA``). The
public key is read from the token's public key object (``CKA_EC_POINT``). ``python-pkcs11``
(the ``token`` extra) is imported only when a ``pkcs11:`` URI is used, so a robot signing
with a key file or not at all does not need it. Everything the token or its module can say
wrong (module missing, token or key not found, wrong PIN, not an Ed25519 key) is one
``UsageError``: a set-up error the operator fixes.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from trace_runtime.errors import StorageError, UsageError
from trace_runtime.tlog.keys import PUBLIC_SUFFIX, PublicKey, public_pem_of
from trace_runtime.tlog.pkcs11_session import (
    find_objects,
    open_session,
    pkcs11_module,
    public_key_raw,
    read_public_raw,
    why,
)
from trace_runtime.tlog.pkcs11_uri import TokenUri, parse_token_uri

__all__ = [
    "TokenKeyPair",
    "TokenSigner",
    "export_token_public_key",
    "generate_token_key",
    "open_token_signer",
    "read_token_public_key",
]

# DER of the Ed25519 curve's OID, 1.3.101.112 (RFC 8410): CKA_EC_PARAMS of an Ed25519 key.
_ED25519_PARAMS = bytes.fromhex("06032b6570")
_PROBE = b"trace-audit token key check\n"


@dataclass(frozen=True, slots=True)
class _Opened:
    session: Any
    key: Any
    public_key: PublicKey


def _open_key(uri: TokenUri) -> _Opened:
    p11 = pkcs11_module()
    session = open_session(uri, rw=False)
    try:
        found = find_objects(session, uri, p11.ObjectClass.PRIVATE_KEY)
        if len(found) != 1:
            hint = "" if uri.pin is not None else " (no PIN given: pin-value or pin-source)"
            count = "no" if not found else str(len(found))
            raise UsageError(f"{uri.describe()}: {count} private key(s) found{hint}")
        key = found[0]
        if key[p11.Attribute.KEY_TYPE] != p11.KeyType.EC_EDWARDS:
            raise UsageError(f"{uri.describe()}: not an Ed25519 key")
        public = PublicKey.from_raw(public_key_raw(session, uri))
        try:
            signature = key.sign(_PROBE, mechanism=p11.Mechanism.EDDSA)
        except p11.PKCS11Error as err:
            raise UsageError(f"{uri.describe()}: the token cannot sign ({why(err)})") from err
        if not public.verify(bytes(signature), _PROBE):
            raise UsageError(f"{uri.describe()}: its private and public key objects differ")
    except BaseException:
        session.close()
        raise
    return _Opened(session, key, public)


class TokenSigner:
    """Signs with an Ed25519 key held in a PKCS#11 token, through one session it keeps open.

    PKCS#11 sessions are not to be used by two threads at once: a lock orders the signatures
    (the logger's writer thread, a witness's request threads)."""

    __slots__ = ("_key", "_lock", "_session", "key_id", "public_key", "uri")

    def __init__(self, uri: TokenUri) -> None:
        opened = _open_key(uri)
        self._session = opened.session
        self._key = opened.key
        self._lock = threading.Lock()
        self.public_key = opened.public_key
        self.key_id = self.public_key.key_id
        self.uri = uri.redacted()

    def sign(self, data: bytes) -> bytes:
        p11 = pkcs11_module()
        with self._lock:
            return bytes(self._key.sign(data, mechanism=p11.Mechanism.EDDSA))

    def close(self) -> None:
        """Close the session (the key stays in the token)."""
        with self._lock:
            self._session.close()

    def __repr__(self) -> str:
        return f"TokenSigner({self.uri!r}, key_id={self.key_id[:16]}…)"


def open_token_signer(uri: str) -> TokenSigner:
    """A signer for the key a ``pkcs11:`` URI names (RFC 7512, with module-path and PIN)."""
    return TokenSigner(parse_token_uri(uri))


@dataclass(frozen=True, slots=True)
class TokenKeyPair:
    """A key made in a token: the URI that names it (without its PIN), where its public key
    was written, and its key id."""

    uri: str
    public_path: Path
    key_id: str


def read_token_public_key(uri: str) -> PublicKey:
    """The public key of the key a ``pkcs11:`` URI names, read from the token's public key
    object (``CKA_EC_POINT``). A public object needs no PIN; one given is used."""
    return PublicKey.from_raw(read_public_raw(parse_token_uri(uri)))


def export_token_public_key(
    uri: str, directory: str | Path, *, name: str | None = None, overwrite: bool = False
) -> TokenKeyPair:
    """Write ``directory/NAME.pub`` (NAME: the object label) of a key the token already
    holds, makes nothing in the token. A ``.pub`` there is replaced only with ``overwrite``
    (``StorageError`` otherwise, as for any key file that exists)."""
    parsed = parse_token_uri(uri)
    public_path = _public_path(parsed, directory, name)
    if public_path.exists() and not overwrite:
        raise StorageError(str(public_path), "a key exists; refusing to overwrite it (--force)")
    public = read_token_public_key(uri)
    try:
        public_path.parent.mkdir(parents=True, exist_ok=True)
        public_path.write_bytes(public_pem_of(public.raw))
    except OSError as err:
        raise StorageError(str(public_path), err.strerror or str(err)) from err
    return TokenKeyPair(parsed.redacted(), public_path, public.key_id)


def _public_path(uri: TokenUri, directory: str | Path, name: str | None) -> Path:
    stem = name or uri.object_label
    if stem is None:
        raise UsageError(f"{uri.redacted()}: name the key's file (--name) or object (object=NAME)")
    if not stem or "/" in stem or stem.startswith("."):
        raise UsageError(f"key name must be a plain file name: {stem!r}")
    return Path(directory) / f"{stem}{PUBLIC_SUFFIX}"


def generate_token_key(
    uri: str, directory: str | Path, *, name: str | None = None, overwrite: bool = False
) -> TokenKeyPair:
    """Generate an Ed25519 key inside the token ``uri`` names (sensitive, not extractable, a
    token object) and write its public key to ``directory/NAME.pub`` (NAME: the object label).

    A key of that label or id already in the token is a ``StorageError`` (exit 4, like a key
    file that exists): a token key is never replaced. A public key that cannot be written is
    a ``StorageError`` too, and the key is taken out of the token again: a key nobody can
    verify signs nothing useful, and would block its name."""
    parsed = parse_token_uri(uri)
    label = parsed.object_label
    if label is None:
        raise UsageError(f"{parsed.redacted()}: a new key needs a label (object=NAME)")
    public_path = _public_path(parsed, directory, name)
    session = open_session(parsed, rw=True)
    try:
        # The token first: --force cannot replace a key the token holds, so the file's
        # refusal below suggests it only when the token has no key of that name.
        _refuse_taken(session, parsed)
        if public_path.exists() and not overwrite:
            raise StorageError(str(public_path), "a key exists; refusing to overwrite it (--force)")
        raw = _generate(session, parsed, label)
        try:
            public_path.parent.mkdir(parents=True, exist_ok=True)
            public_path.write_bytes(public_pem_of(raw))
        except OSError as err:
            _destroy(session, parsed)
            raise StorageError(str(public_path), err.strerror or str(err)) from err
    finally:
        session.close()
    return TokenKeyPair(parsed.redacted(), public_path, PublicKey.from_raw(raw).key_id)


def _refuse_taken(session: Any, uri: TokenUri) -> None:
    p11 = pkcs11_module()
    taken = [
        *find_objects(session, uri, p11.ObjectClass.PRIVATE_KEY),
        *find_objects(session, uri, p11.ObjectClass.PUBLIC_KEY),
    ]
    if taken:
        raise StorageError(
            uri.describe(),
            "it exists; a key in a token is never replaced (--public-only writes its "
            "public key again)",
        )


def _generate(session: Any, uri: TokenUri, label: str) -> bytes:
    p11 = pkcs11_module()
    attr = p11.Attribute
    try:
        session.generate_keypair(
            p11.KeyType.EC_EDWARDS,
            None,
            id=uri.object_id or os.urandom(16),  # pairs the two objects, as p11tool does
            label=label,
            store=True,
            mechanism=p11.Mechanism.EC_EDWARDS_KEY_PAIR_GEN,
            public_template={attr.EC_PARAMS: _ED25519_PARAMS, attr.VERIFY: True},
            private_template={
                attr.SENSITIVE: True,
                attr.EXTRACTABLE: False,
                attr.PRIVATE: True,
                attr.SIGN: True,
            },
        )
    except p11.PKCS11Error as err:
        raise UsageError(
            f"{uri.describe()}: the token cannot make an Ed25519 key ({why(err)})"
        ) from err
    return public_key_raw(session, uri)


def _destroy(session: Any, uri: TokenUri) -> None:
    """Take the key just made out of the token (both its objects)."""
    p11 = pkcs11_module()
    for object_class in (p11.ObjectClass.PRIVATE_KEY, p11.ObjectClass.PUBLIC_KEY):
        for obj in find_objects(session, uri, object_class):
            obj.destroy()
