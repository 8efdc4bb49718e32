"""Ed25519 key files for checkpoint signatures: written owner-only, never overwritten unless
asked, loaded from PEM, OpenSSH or raw bytes; a bad key file is a usage error."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest
from cryptography.hazmat.primitives.asymmetric.x25519 import X25519PrivateKey
from cryptography.hazmat.primitives.serialization import (
    Encoding,
    NoEncryption,
    PrivateFormat,
    PublicFormat,
)

from trace_runtime.errors import StorageError, UsageError
from trace_runtime.tlog.keys import Ed25519Signer, generate_keypair, load_public_key, load_signer

# --- keys ------------------------------------------------------------------------------------


def test_keygen_writes_a_private_key_only_its_owner_can_read(tmp_path: Path) -> None:
    pair = generate_keypair(tmp_path / "keys")
    assert stat.S_IMODE(os.stat(pair.private_path).st_mode) == 0o600
    assert pair.private_path.read_bytes().startswith(b"-----BEGIN PRIVATE KEY-----")
    assert pair.public_path.read_bytes().startswith(b"-----BEGIN PUBLIC KEY-----")
    signer, public = load_signer(pair.private_path), load_public_key(pair.public_path)
    assert signer.key_id == public.key_id == pair.key_id
    assert public.verify(signer.sign(b"x"), b"x") and not public.verify(signer.sign(b"x"), b"y")


def test_keygen_refuses_to_overwrite_a_key_unless_forced(tmp_path: Path) -> None:
    first = generate_keypair(tmp_path)
    with pytest.raises(StorageError, match="refusing to overwrite"):
        generate_keypair(tmp_path)
    os.chmod(first.private_path, 0o644)
    second = generate_keypair(tmp_path, overwrite=True)
    assert second.key_id != first.key_id
    assert stat.S_IMODE(os.stat(second.private_path).st_mode) == 0o600


def test_raw_and_openssh_key_files_load(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    key = signer._key
    raw_private = key.private_bytes(Encoding.Raw, PrivateFormat.Raw, NoEncryption())
    (tmp_path / "raw.key").write_bytes(raw_private)
    public = key.public_key()
    (tmp_path / "raw.pub").write_bytes(public.public_bytes(Encoding.Raw, PublicFormat.Raw))
    (tmp_path / "ssh.pub").write_bytes(public.public_bytes(Encoding.OpenSSH, PublicFormat.OpenSSH))
    assert load_signer(tmp_path / "raw.key").key_id == signer.key_id
    assert load_public_key(tmp_path / "raw.pub").key_id == signer.key_id
    assert load_public_key(tmp_path / "ssh.pub").key_id == signer.key_id


def test_bad_key_files_are_usage_errors(tmp_path: Path) -> None:
    pair = generate_keypair(tmp_path)
    (tmp_path / "junk").write_bytes(b"not a key at all\n")
    x25519 = X25519PrivateKey.generate().private_bytes(
        Encoding.PEM, PrivateFormat.PKCS8, NoEncryption()
    )
    (tmp_path / "x25519.key").write_bytes(x25519)
    with pytest.raises(UsageError, match="private key; verify with the public key"):
        load_public_key(pair.private_path)
    with pytest.raises(UsageError, match="no such file"):
        load_public_key(tmp_path / "missing.pub")
    with pytest.raises(UsageError, match="not a PEM"):
        load_public_key(tmp_path / "junk")
    with pytest.raises(UsageError, match="not an Ed25519 key"):
        load_signer(tmp_path / "x25519.key")
