"""A SoftHSM2 token of a test's own: its configuration and token folder under ``tmp_path``
(``SOFTHSM2_CONF`` set for the test and the processes it starts), initialised with
``softhsm2-util --init-token --free``. Without SoftHSM2 (Debian's ``softhsm2``) or
python-pkcs11 (the ``token`` extra) the test is skipped, saying which is missing."""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

MODULE = Path("/usr/lib/softhsm/libsofthsm2.so")
PIN = "1234"
SO_PIN = "12345678"


@dataclass(frozen=True)
class SoftHsm:
    """One initialised token, by label, and the ``pkcs11:`` URIs that name keys in it."""

    conf: Path
    label: str
    module: Path = MODULE

    def uri(self, obj: str, *, pin: str | None = PIN, extra: str = "") -> str:
        query = f"module-path={self.module}"
        if pin is not None:
            query += f"&pin-value={pin}"
        return f"pkcs11:token={self.label};object={obj}?{query}{extra}"


def softhsm_token(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, label: str = "robot") -> SoftHsm:
    """A fresh token in a SoftHSM2 of the test's own (skips when SoftHSM2 is absent)."""
    util = shutil.which("softhsm2-util")
    if util is None or not MODULE.exists():
        pytest.skip("SoftHSM2 not installed (Debian's softhsm2: softhsm2-util, libsofthsm2.so)")
    pkcs11 = pytest.importorskip("pkcs11", reason="python-pkcs11 (the token extra) missing")
    tokens = tmp_path / "softhsm-tokens"
    tokens.mkdir()
    conf = tmp_path / "softhsm2.conf"
    conf.write_text(
        f"directories.tokendir = {tokens}\nobjectstore.backend = file\nlog.level = ERROR\n"
    )
    monkeypatch.setenv("SOFTHSM2_CONF", str(conf))
    subprocess.run(
        [util, "--init-token", "--free", "--label", label, "--pin", PIN, "--so-pin", SO_PIN],
        check=True,
        capture_output=True,
    )
    # python-pkcs11 keeps a module loaded per process and SoftHSM2 reads its configuration
    # when initialised: start it again so that this test's token folder is the one it sees.
    pkcs11.lib(str(MODULE)).reinitialize()
    return SoftHsm(conf, label)
