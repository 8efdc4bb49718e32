"""The one reading of a key argument (``--key``, ``LoggerConfig.checkpoint_key``): a key
file's path (``keys.load_signer``) or an RFC 7512 ``pkcs11:`` URI naming a key held in a
token (``token.open_token_signer``, which needs the ``token`` extra)."""

from __future__ import annotations

from pathlib import Path

from trace_runtime.tlog.keys import Ed25519Signer, load_signer
from trace_runtime.tlog.pkcs11_uri import is_token_uri
from trace_runtime.tlog.token import TokenSigner, open_token_signer

__all__ = ["open_signer"]


def open_signer(key: str | Path) -> Ed25519Signer | TokenSigner:
    """The signer a key argument names: a ``pkcs11:`` URI (a ``str``) opens the key in its
    token; anything else is a key file. Every failure is a ``UsageError``."""
    if isinstance(key, str) and is_token_uri(key):
        return open_token_signer(key)
    return load_signer(key)
