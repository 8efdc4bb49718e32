"""PKCS#11 sessions on the token an RFC 7512 URI names, and the raw Ed25519 public key of the
key it names (``CKA_EC_POINT`` of its public key object): what signing through a token
(``token``) and reading a token key's public key (``keys.load_public_key``) share.

``python-pkcs11`` (the ``token`` extra) is imported on first use. Everything the module or
the token can say wrong is one ``UsageError``: a set-up error the operator fixes.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

from trace_runtime.errors import UsageError
from trace_runtime.tlog.pkcs11_uri import TokenUri

__all__ = [
    "find_objects",
    "open_session",
    "pkcs11_module",
    "public_key_raw",
    "read_public_raw",
    "why",
]


def pkcs11_module() -> ModuleType:
    """python-pkcs11, imported on first use (the ``token`` extra)."""
    try:
        import pkcs11
    except ImportError as err:
        raise UsageError(
            "a pkcs11: key needs python-pkcs11: pip install 'trace-audit[token]'"
        ) from err
    return pkcs11


def _token(uri: TokenUri) -> Any:
    """The token the URI names, in the module it names."""
    p11 = pkcs11_module()
    module = uri.module_path or ""
    try:
        lib = p11.lib(module)
    except p11.PKCS11Error as err:  # python-pkcs11 reports dlopen failures as PKCS11Error
        raise UsageError(f"PKCS#11 module {module}: cannot load ({err})") from err
    query: dict[str, object] = {}
    if uri.token_label is not None:
        query["token_label"] = uri.token_label
    if "serial" in uri.path:
        query["token_serial"] = uri.path["serial"]
    try:
        tokens = list(lib.get_tokens(**query))
    except p11.PKCS11Error as err:
        raise UsageError(f"PKCS#11 module {module}: cannot list tokens ({why(err)})") from err
    if len(tokens) != 1:
        which = uri.token_label or "(unnamed)"
        found = "no" if not tokens else f"{len(tokens)}"
        raise UsageError(f"PKCS#11 module {module}: {found} token(s) match token={which!r}")
    return tokens[0]


def why(err: BaseException) -> str:
    """A PKCS#11 error in words: python-pkcs11 often raises its typed errors without text."""
    return str(err) or type(err).__name__


def open_session(uri: TokenUri, *, rw: bool) -> Any:
    """A session on the URI's token, logged in with its PIN when it gives one."""
    p11 = pkcs11_module()
    token = _token(uri)
    try:
        return token.open(rw=rw, user_pin=uri.pin)
    except p11.exceptions.UserAlreadyLoggedIn:
        # PKCS#11 logs in per process, not per session: another signer on this token (the
        # old key of a rotation) already did, and its login holds for this session too.
        return token.open(rw=rw)
    except (p11.exceptions.PinIncorrect, p11.exceptions.PinLenRange) as err:
        raise UsageError(f"token {token.label!r}: wrong PIN") from err
    except p11.exceptions.PinLocked as err:
        raise UsageError(f"token {token.label!r}: PIN locked (too many wrong PINs)") from err
    except p11.PKCS11Error as err:
        raise UsageError(f"token {token.label!r}: cannot log in ({why(err)})") from err


def find_objects(session: Any, uri: TokenUri, object_class: Any) -> Any:
    """The objects of ``object_class`` the URI names (by label and id) in the session."""
    p11 = pkcs11_module()
    attrs: dict[Any, object] = {p11.Attribute.CLASS: object_class}
    if uri.object_label is not None:
        attrs[p11.Attribute.LABEL] = uri.object_label
    if uri.object_id is not None:
        attrs[p11.Attribute.ID] = uri.object_id
    try:
        found = list(session.get_objects(attrs))
    except p11.PKCS11Error as err:
        raise UsageError(f"{uri.describe()}: cannot search ({why(err)})") from err
    return found


def public_key_raw(session: Any, uri: TokenUri) -> bytes:
    """The raw 32-byte Ed25519 public key of the URI's key, from its ``CKA_EC_POINT``."""
    p11 = pkcs11_module()
    found = find_objects(session, uri, p11.ObjectClass.PUBLIC_KEY)
    if len(found) != 1:
        count = "no" if not found else str(len(found))
        raise UsageError(f"{uri.describe()}: {count} public key object(s) found")
    try:
        point = bytes(found[0][p11.Attribute.EC_POINT])
    except p11.PKCS11Error as err:
        raise UsageError(f"{uri.describe()}: not an EC key ({why(err)})") from err
    # PKCS#11 3.0 wraps the point in a DER OCTET STRING; some tokens give it bare.
    if len(point) == 34 and point[:2] == b"\x04\x20":
        point = point[2:]
    if len(point) != 32:
        raise UsageError(f"{uri.describe()}: not an Ed25519 key ({len(point)}-byte point)")
    return point


def read_public_raw(uri: TokenUri) -> bytes:
    """The raw public key of the URI's key, in a session of its own (a public object needs
    no PIN; one given is used)."""
    session = open_session(uri, rw=False)
    try:
        return public_key_raw(session, uri)
    finally:
        session.close()
