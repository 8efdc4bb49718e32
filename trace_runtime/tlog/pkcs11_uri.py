"""RFC 7512 ``pkcs11:`` URIs naming a key in a token: parsed into a ``TokenUri``.

Path attributes (``;``-separated) say which token and object; query attributes
(``&``-separated) say how to reach it: the module (``module-path``) and the PIN
(``pin-value``, or ``pin-source`` naming a file). Every value is percent-decoded (RFC 7512
section 2.3); an attribute given twice, an attribute this reader does not know, or a malformed
escape is a ``UsageError``: a URI that names a key loosely could sign with another key. The
PIN never appears in ``redacted()``, the form messages and ``keygen`` print.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from trace_runtime.errors import UsageError

__all__ = ["PKCS11_SCHEME", "TokenUri", "is_token_uri", "parse_token_uri"]

PKCS11_SCHEME = "pkcs11:"

# RFC 7512 section 2.3: the path attributes that name a token and an object in it.
_PATH_ATTRS = frozenset(
    {
        "token",
        "manufacturer",
        "serial",
        "model",
        "library-manufacturer",
        "library-description",
        "library-version",
        "slot-description",
        "slot-manufacturer",
        "slot-id",
        "object",
        "id",
        "type",
    }
)
_QUERY_ATTRS = frozenset({"module-path", "module-name", "pin-value", "pin-source"})
_ESCAPE = re.compile(r"%([0-9A-Fa-f]{2})")
_MAX_PIN_FILE = 4096


@dataclass(frozen=True, slots=True)
class TokenUri:
    """A key in a PKCS#11 token as an RFC 7512 URI names it (values decoded)."""

    text: str
    path: dict[str, bytes]
    """Path attributes, decoded to bytes (``id`` is binary; the others are UTF-8 text)."""
    module_path: str | None
    pin: str | None
    """The user PIN, from ``pin-value`` or read from the ``pin-source`` file."""

    def attr(self, name: str) -> str | None:
        """A text path attribute (``token``, ``object``, ``serial`` ...), None when absent."""
        value = self.path.get(name)
        return None if value is None else value.decode("utf-8", "replace")

    @property
    def token_label(self) -> str | None:
        return self.attr("token")

    @property
    def object_label(self) -> str | None:
        return self.attr("object")

    @property
    def object_id(self) -> bytes | None:
        return self.path.get("id")

    def redacted(self) -> str:
        """The URI without its PIN: what may be printed, logged or written to a file."""
        head, _, query = self.text.partition("?")
        kept = [q for q in query.split("&") if q and not q.lower().startswith("pin-value=")]
        return head + ("?" + "&".join(kept) if kept else "")

    def describe(self) -> str:
        """Token and object in words, for one-line errors."""
        token = self.token_label or self.attr("serial") or "any token"
        name = self.object_label or (self.object_id.hex() if self.object_id else "any object")
        return f"object {name!r} in token {token!r}"


def is_token_uri(value: object) -> bool:
    """Whether a key argument is a ``pkcs11:`` URI rather than a key file's path."""
    return isinstance(value, str) and value[: len(PKCS11_SCHEME)].lower() == PKCS11_SCHEME


def _decode(value: str, uri: str) -> bytes:
    """Percent-decode one attribute value to bytes; a stray ``%`` is an error."""
    out = bytearray()
    i = 0
    while i < len(value):
        if value[i] == "%":
            match = _ESCAPE.match(value, i)
            if match is None:
                raise UsageError(f"{_safe(uri)}: bad percent escape at {value[i : i + 3]!r}")
            out.append(int(match.group(1), 16))
            i += 3
        else:
            out.extend(value[i].encode())
            i += 1
    return bytes(out)


def _safe(uri: str) -> str:
    """The URI for an error message, PIN removed (the parse may fail before redacted())."""
    return re.sub(r"pin-value=[^&]*", "pin-value=…", uri, flags=re.IGNORECASE)


def _attributes(part: str, sep: str, known: frozenset[str], uri: str) -> dict[str, bytes]:
    found: dict[str, bytes] = {}
    for item in part.split(sep):
        if not item:
            continue
        name, eq, value = item.partition("=")
        name = name.lower()
        if not eq:
            raise UsageError(f"{_safe(uri)}: attribute {name!r} has no '='")
        if name not in known:
            raise UsageError(f"{_safe(uri)}: unknown attribute {name!r} (RFC 7512)")
        if name in found:
            raise UsageError(f"{_safe(uri)}: attribute {name!r} given twice")
        found[name] = _decode(value, uri)
    return found


def parse_token_uri(uri: str) -> TokenUri:
    """Parse a ``pkcs11:`` URI naming one key and how to reach it (module and PIN)."""
    if not is_token_uri(uri):
        raise UsageError(f"not a pkcs11: URI: {_safe(uri)!r}")
    body = uri[len(PKCS11_SCHEME) :]
    if "#" in body:
        raise UsageError(f"{_safe(uri)}: a pkcs11 URI has no fragment")
    path_part, _, query_part = body.partition("?")
    path = _attributes(path_part, ";", _PATH_ATTRS, uri)
    query = _attributes(query_part, "&", _QUERY_ATTRS, uri)
    if "type" in path and path["type"] not in (b"private", b"public"):
        raise UsageError(f"{_safe(uri)}: type={path['type'].decode()!r}: a key is private")
    if "object" not in path and "id" not in path:
        raise UsageError(f"{_safe(uri)}: name the key (object=LABEL or id=%XX...)")
    if "pin-value" in query and "pin-source" in query:
        raise UsageError(f"{_safe(uri)}: give pin-value or pin-source, not both")
    if "module-name" in query:
        raise UsageError(
            f"{_safe(uri)}: module-name is not searched for; give module-path=/path/to/module.so"
        )
    if "module-path" not in query:
        raise UsageError(f"{_safe(uri)}: no module-path=/path/to/the PKCS#11 module.so")
    pin: str | None = None
    if "pin-value" in query:
        pin = query["pin-value"].decode("utf-8")
    elif "pin-source" in query:
        pin = _read_pin(query["pin-source"].decode("utf-8"), uri)
    return TokenUri(uri, path, query["module-path"].decode("utf-8"), pin)


def _read_pin(source: str, uri: str) -> str:
    """The PIN from a ``pin-source``: a ``file:`` URI or a plain path (RFC 7512 2.4); a
    trailing line end is not part of it (a file written by ``echo``)."""
    if source.startswith("file://"):
        rest = source[len("file://") :]
        if not rest.startswith("/"):  # file://host/path: only this host's files exist here
            raise UsageError(f"{_safe(uri)}: pin-source must be a local file:///path")
        source = rest
    elif source.startswith("file:"):
        source = source[len("file:") :]
    elif ":" in source.split("/", 1)[0]:
        raise UsageError(f"{_safe(uri)}: pin-source must be a file: URI or a path")
    path = Path(source)
    try:
        with path.open("rb") as f:
            data = f.read(_MAX_PIN_FILE + 1)
    except OSError as err:
        raise UsageError(f"pin-source {path}: cannot read ({err.strerror or err})") from err
    if len(data) > _MAX_PIN_FILE:
        raise UsageError(f"pin-source {path}: over {_MAX_PIN_FILE} bytes, not a PIN")
    return data.decode("utf-8", "replace").rstrip("\r\n")
