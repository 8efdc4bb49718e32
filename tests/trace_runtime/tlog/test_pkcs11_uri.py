"""RFC 7512 ``pkcs11:`` URIs: path and query attributes apart, every value percent-decoded,
the PIN from ``pin-value`` or a ``pin-source`` file, and anything loose (an unknown or
repeated attribute, a bad escape, no module) refused with a usage error that never shows
the PIN."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from trace_runtime.errors import UsageError
from trace_runtime.tlog.pkcs11_uri import is_token_uri, parse_token_uri
from trace_runtime.tlog.signers import open_signer

MODULE = "module-path=/usr/lib/softhsm/libsofthsm2.so"


def test_path_and_query_attributes_are_told_apart_and_decoded() -> None:
    uri = parse_token_uri(
        f"pkcs11:token=Robot%20HSM;object=amr%2D7;id=%01%ff;type=private?{MODULE}&pin-value=12%2634"
    )
    assert uri.token_label == "Robot HSM"
    assert uri.object_label == "amr-7"
    assert uri.object_id == b"\x01\xff"
    assert uri.module_path == "/usr/lib/softhsm/libsofthsm2.so"
    assert uri.pin == "12&34"  # an escaped '&' is part of the PIN, not a separator
    assert "12" not in uri.redacted() and uri.redacted().endswith(MODULE)


def test_a_pin_source_file_is_read_without_its_line_end(tmp_path: Path) -> None:
    (tmp_path / "pin").write_text("4321\n")
    for source in (f"file:{tmp_path}/pin", f"file://{tmp_path}/pin", f"{tmp_path}/pin"):
        assert parse_token_uri(f"pkcs11:object=k?{MODULE}&pin-source={source}").pin == "4321"
    with pytest.raises(UsageError, match=r"pin-source .*cannot read"):
        parse_token_uri(f"pkcs11:object=k?{MODULE}&pin-source=file:{tmp_path}/none")
    with pytest.raises(UsageError, match="local file"):
        parse_token_uri(f"pkcs11:object=k?{MODULE}&pin-source=file://host{tmp_path}/pin")


@pytest.mark.parametrize(
    ("uri", "says"),
    [
        (f"pkcs11:token=a;objet=k?{MODULE}", "unknown attribute 'objet'"),
        (f"pkcs11:object=k;object=j?{MODULE}", "given twice"),
        (f"pkcs11:object=k%4?{MODULE}", "bad percent escape"),
        (f"pkcs11:object=k%zz?{MODULE}", "bad percent escape"),
        ("pkcs11:object=k", "no module-path"),
        ("pkcs11:object=k?module-name=softhsm2", "module-name is not searched"),
        (f"pkcs11:token=a?{MODULE}", "name the key"),
        (f"pkcs11:object=k;type=cert?{MODULE}", "a key is private"),
        (f"pkcs11:object=k?{MODULE}&pin-value=1&pin-source=/p", "not both"),
        (f"pkcs11:object=k?{MODULE}#frag", "no fragment"),
        (f"pkcs11:object?{MODULE}", "no '='"),
    ],
)
def test_a_loose_uri_is_a_usage_error(uri: str, says: str) -> None:
    with pytest.raises(UsageError, match=says):
        parse_token_uri(uri)


def test_an_error_never_shows_the_pin() -> None:
    with pytest.raises(UsageError) as raised:
        parse_token_uri(f"pkcs11:object=k;bogus=1?{MODULE}&PIN-VALUE=secret-pin")
    assert "secret-pin" not in str(raised.value)


def test_a_key_file_path_is_not_a_uri(tmp_path: Path) -> None:
    assert is_token_uri("PKCS11:object=k") and not is_token_uri(str(tmp_path / "pkcs11.key"))
    assert not is_token_uri(tmp_path / "x")
    with pytest.raises(UsageError, match="no such file"):
        open_signer(tmp_path / "pkcs11:object=k")  # a Path is always a file


@given(st.binary(min_size=1, max_size=40))
def test_any_label_bytes_survive_percent_encoding(raw: bytes) -> None:
    encoded = "".join(f"%{b:02x}" for b in raw)
    assert parse_token_uri(f"pkcs11:id={encoded}?{MODULE}").object_id == raw
