"""Keys in a PKCS#11 token (SoftHSM2): generated inside it as sensitive, unextractable token
objects, signing through it with signatures the written public key verifies, from many
threads at once, and refusing, for real, every way of getting the private key out."""

from __future__ import annotations

import shutil
import subprocess
import threading
from pathlib import Path

import pytest

from tests.softhsm import PIN, SoftHsm, softhsm_token
from trace_runtime.errors import StorageError, UsageError
from trace_runtime.tlog.keys import load_public_key
from trace_runtime.tlog.signers import open_signer
from trace_runtime.tlog.token import TokenSigner, generate_token_key


@pytest.fixture
def hsm(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> SoftHsm:
    return softhsm_token(tmp_path, monkeypatch)


def test_a_token_key_signs_what_its_written_public_key_verifies(
    hsm: SoftHsm, tmp_path: Path
) -> None:
    made = generate_token_key(hsm.uri("amr-7"), tmp_path / "keys")
    assert made.public_path == tmp_path / "keys" / "amr-7.pub"
    assert "pin-value" not in made.uri and PIN not in made.uri
    assert [p.name for p in (tmp_path / "keys").iterdir()] == ["amr-7.pub"]
    public = load_public_key(made.public_path)
    signer = open_signer(hsm.uri("amr-7"))
    assert isinstance(signer, TokenSigner)
    assert signer.key_id == public.key_id == made.key_id
    assert public.verify(signer.sign(b"head"), b"head")
    assert not public.verify(signer.sign(b"head"), b"tail")


def test_the_key_is_sensitive_unextractable_and_kept_in_the_token(
    hsm: SoftHsm, tmp_path: Path
) -> None:
    import pkcs11
    from pkcs11 import Attribute, KeyType, ObjectClass

    generate_token_key(hsm.uri("amr-7"), tmp_path)
    token = pkcs11.lib(str(hsm.module)).get_token(token_label=hsm.label)
    with token.open(rw=True, user_pin=PIN) as session:
        key = session.get_key(ObjectClass.PRIVATE_KEY, label="amr-7")
        assert key[Attribute.SENSITIVE] is True
        assert key[Attribute.EXTRACTABLE] is False
        assert key[Attribute.TOKEN] is True
        assert key[Attribute.NEVER_EXTRACTABLE] is True
        with pytest.raises(pkcs11.exceptions.AttributeSensitive):
            key[Attribute.VALUE]
        # Wrapping is how a token exports a key; an unextractable key cannot be wrapped.
        wrapping = session.generate_key(KeyType.AES, 256, store=False)
        with pytest.raises(pkcs11.exceptions.KeyUnextractable):
            wrapping.wrap_key(key)


def test_the_token_tools_cannot_export_the_key(hsm: SoftHsm, tmp_path: Path) -> None:
    generate_token_key(hsm.uri("amr-7"), tmp_path)
    tried = 0
    helps = subprocess.run(["softhsm2-util", "--help"], check=False, capture_output=True, text=True)
    if "--export" in helps.stdout + helps.stderr:
        tried += 1
        exported = subprocess.run(
            ["softhsm2-util", "--export", str(tmp_path / "out.pem"), "--token", hsm.label,
             "--label", "amr-7", "--pin", PIN], check=False, capture_output=True, text=True,
        )  # fmt: skip
        assert exported.returncode != 0 and not (tmp_path / "out.pem").exists()
    tool = shutil.which("pkcs11-tool")
    if tool is not None:
        tried += 1
        read = subprocess.run(
            [tool, "--module", str(hsm.module), "--token-label", hsm.label, "--login",
             "--pin", PIN, "--read-object", "--type", "privkey", "--label", "amr-7"],
            check=False, capture_output=True,
        )  # fmt: skip
        assert read.returncode != 0, read.stdout
    if not tried:
        pytest.skip("no exporting tool here: softhsm2-util has no --export, no pkcs11-tool")


def test_a_key_is_never_replaced_in_the_token(hsm: SoftHsm, tmp_path: Path) -> None:
    first = generate_token_key(hsm.uri("amr-7"), tmp_path / "a")
    with pytest.raises(StorageError, match="never replaced"):
        generate_token_key(hsm.uri("amr-7"), tmp_path / "b", overwrite=True)
    assert not (tmp_path / "b").exists()
    assert open_signer(hsm.uri("amr-7")).key_id == first.key_id


def test_a_public_key_that_cannot_be_written_leaves_no_key_in_the_token(
    hsm: SoftHsm, tmp_path: Path
) -> None:
    (tmp_path / "a-file").write_text("not a folder")
    with pytest.raises(StorageError, match="a-file"):
        generate_token_key(hsm.uri("amr-7"), tmp_path / "a-file")
    with pytest.raises(UsageError, match="no private key"):
        open_signer(hsm.uri("amr-7"))
    assert generate_token_key(hsm.uri("amr-7"), tmp_path / "keys").public_path.exists()


def test_one_signer_signs_from_many_threads(hsm: SoftHsm, tmp_path: Path) -> None:
    made = generate_token_key(hsm.uri("amr-7"), tmp_path)
    public, signer = load_public_key(made.public_path), open_signer(hsm.uri("amr-7"))
    bad: list[int] = []

    def sign(n: int) -> None:
        for i in range(40):
            data = f"{n}:{i}".encode()
            if not public.verify(signer.sign(data), data):
                bad.append(n)

    threads = [threading.Thread(target=sign, args=(n,)) for n in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert bad == []


@pytest.mark.parametrize(
    ("uri_of", "says"),
    [
        (lambda h: h.uri("nokey"), "object 'nokey' in token 'robot': no private key(s) found"),
        (lambda h: h.uri("amr-7").replace("token=robot", "token=other"), "no token(s) match"),
        (lambda h: h.uri("amr-7").replace(str(h.module), "/nonexistent.so"), "cannot load"),
    ],
)
def test_what_cannot_be_found_is_a_usage_error(
    hsm: SoftHsm, tmp_path: Path, uri_of: object, says: str
) -> None:
    generate_token_key(hsm.uri("amr-7"), tmp_path)
    assert callable(uri_of)
    with pytest.raises(UsageError) as raised:
        open_signer(uri_of(hsm))
    assert says in str(raised.value)
