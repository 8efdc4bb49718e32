"""Keys in a token from the outside, with SoftHSM2: ``keygen --token`` makes the key in the
token and writes only its public key, ``trace-sim run --key URI`` signs through the token,
and ``verify --key`` with the written public key finds the log CLEAN. Whatever is wrong
with the token (a wrong PIN, a module that does not load, the extra not installed) is one
line and exit 2, from every command that takes a key."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import REPO, cli, one_line
from tests.softhsm import SoftHsm, softhsm_token
from tests.trace_audit.conftest import fill_cycle
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.tlog.keys import generate_keypair, load_public_key
from trace_runtime.tlog.signed_note import COSIGNATURE, verifier_key


@pytest.fixture
def hsm(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> SoftHsm:
    return softhsm_token(tmp_path, monkeypatch)


def sim(*args: str | Path, pythonpath: str = str(REPO)) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "evaluation.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": pythonpath},
        timeout=300,
    )


def test_a_sim_log_signed_in_the_token_verifies_clean(hsm: SoftHsm, tmp_path: Path) -> None:
    made = cli("keygen", "--out", tmp_path / "keys", "--token", hsm.uri("amr-7"), "--json")
    assert made.returncode == 0, made.stderr
    key = json.loads(made.stdout)
    assert sorted(p.name for p in (tmp_path / "keys").iterdir()) == ["amr-7.pub"]
    assert "pin-value" not in key["uri"]
    pin = tmp_path / "pin"
    pin.write_text("1234\n")
    uri = hsm.uri("amr-7", pin=None, extra=f"&pin-source=file:{pin}")
    ran = sim("run", "--cycles", "40", "--out", tmp_path / "log", "--key", uri)
    assert ran.returncode == 0, ran.stderr
    checked = cli("verify", tmp_path / "log", "--key", key["public_path"], "--json")
    report = json.loads(checked.stdout)
    assert checked.returncode == 0 and report["findings"] == []
    assert report["checkpoints_valid"] == report["checkpoints"] > 0
    assert report["key_id"] == key["key_id"]
    # Another key (made in the same token) does not vouch for it: the signatures are real.
    cli("keygen", "--out", tmp_path / "keys", "--token", hsm.uri("other"))
    other = cli("verify", tmp_path / "log", "--key", tmp_path / "keys" / "other.pub", "--json")
    assert other.returncode == 1
    assert {f["kind"] for f in json.loads(other.stdout)["findings"]} == {"key_mismatch"}


def test_a_wrong_pin_is_one_line_from_every_command(hsm: SoftHsm, tmp_path: Path) -> None:
    assert cli("keygen", "--out", tmp_path, "--token", hsm.uri("amr-7")).returncode == 0
    wrong = hsm.uri("amr-7", pin="9999")
    one_line(cli("keygen", "--out", tmp_path / "k", "--token", hsm.uri("k2", pin="9")), 2,
             "token 'robot': wrong PIN")  # fmt: skip
    one_line(sim("run", "--cycles", "3", "--out", tmp_path / "log", "--key", wrong), 2,
             "wrong PIN")  # fmt: skip
    vkey = verifier_key("trace.local/amr-7", load_public_key(tmp_path / "amr-7.pub").raw)
    one_line(cli("witness", "serve", "--state", tmp_path / "st", "--key", wrong, "--log", vkey),
             2, "wrong PIN")  # fmt: skip
    recorder = subprocess.run(
        [sys.executable, "-m", "trace_runtime.recorder.cli", "serve", "--root", tmp_path / "rec",
         "--socket", tmp_path / "rec.sock", "--key", wrong],
        capture_output=True, text=True, check=False, timeout=120,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    one_line(recorder, 2, "trace-recorder: token 'robot': wrong PIN")
    assert not (tmp_path / "log").exists() or not list((tmp_path / "log").rglob("*.mcap"))


def test_a_module_that_does_not_load_is_one_line(hsm: SoftHsm, tmp_path: Path) -> None:
    uri = hsm.uri("amr-7").replace(str(hsm.module), str(tmp_path / "none.so"))
    one_line(cli("keygen", "--out", tmp_path, "--token", uri), 2, "none.so: cannot load")


def test_without_the_token_extra_a_token_key_is_one_line(hsm: SoftHsm, tmp_path: Path) -> None:
    # A python-pkcs11 that is not there: a package of that name that fails to import, first
    # on the path, as an install without the extra behaves.
    missing = tmp_path / "no-extra" / "pkcs11"
    missing.mkdir(parents=True)
    (missing / "__init__.py").write_text("raise ImportError('not installed')\n")
    path = f"{missing.parent}{os.pathsep}{REPO}"
    done = sim("run", "--cycles", "3", "--out", tmp_path / "log", "--key", hsm.uri("amr-7"),
               pythonpath=path)  # fmt: skip
    one_line(done, 2, "pip install 'trace-audit[token]'")


def test_a_witness_cosigns_with_a_key_in_a_token(hsm: SoftHsm, tmp_path: Path) -> None:
    """``witness serve --key URI``: the robot's logger submits to it, and its cosignatures,
    made in the token, check under the verifier key of the public key keygen wrote."""
    assert cli("keygen", "--out", tmp_path, "--token", hsm.uri("witness")).returncode == 0
    robot = generate_keypair(tmp_path, name="amr-7")
    robot_vkey = verifier_key("trace.local/amr-7", load_public_key(robot.public_path).raw)
    witness_vkey = verifier_key(
        "trace.local/witness", load_public_key(tmp_path / "witness.pub").raw, COSIGNATURE
    )
    process = subprocess.Popen(
        [sys.executable, "-m", "trace_audit.cli", "witness", "serve", "--listen", "127.0.0.1:0",
         "--state", str(tmp_path / "state"), "--key", hsm.uri("witness"), "--log", robot_vkey],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    try:
        assert process.stderr is not None
        line = process.stderr.readline()
        assert f"as {witness_vkey} " in line, line
        url = line.split("listening on ", 1)[1].split()[0]
        config = LoggerConfig(threaded=False, fsync_interval_s=None, checkpoint_interval_s=1.0,
                              checkpoint_key=robot.private_path, witness=url)  # fmt: skip
        logger = AuditLogger(tmp_path / "root", robot_id="amr-7", period_s=0.1, config=config)
        for i in range(30):
            with logger.cycle(1_790_000_000_000_000_000 + i * 100_000_000) as c:
                fill_cycle(c, "clear")
        logger.close()
        assert logger.stats.witness_cosigned > 0 and logger.stats.witness_failures == 0
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=20) == 0
        if process.stderr is not None:
            process.stderr.close()
    checked = cli("verify", tmp_path / "root", "--key", robot.public_path, "--witness", "local",
                  "--witness-key", witness_vkey, "--json")  # fmt: skip
    assert checked.returncode == 0, checked.stdout
    # The same check with another key than the witness's: the cosignatures are really checked.
    other = verifier_key("trace.local/witness", load_public_key(robot.public_path).raw, COSIGNATURE)
    forged = cli("verify", tmp_path / "root", "--key", robot.public_path, "--witness", "local",
                 "--witness-key", other, "--json")  # fmt: skip
    assert forged.returncode == 1
    assert {f["kind"] for f in json.loads(forged.stdout)["findings"]} == {"bad_signature"}


def test_a_token_key_s_public_key_is_read_back_from_the_token(hsm: SoftHsm, tmp_path: Path) -> None:
    """A lost .pub is no lost key: verify, publish, witness vkey and keygen --public-only
    read the public key from the token's public key object, by the key's URI (no PIN
    needed)."""
    made = json.loads(cli("keygen", "--out", tmp_path / "keys", "--token", hsm.uri("amr-7"),
                          "--json").stdout)  # fmt: skip
    original = Path(made["public_path"]).read_bytes()
    ran = sim("run", "--cycles", "30", "--out", tmp_path / "log", "--key", hsm.uri("amr-7"))
    assert ran.returncode == 0, ran.stderr
    Path(made["public_path"]).unlink()
    for uri in (hsm.uri("amr-7"), hsm.uri("amr-7", pin=None)):
        checked = cli("verify", tmp_path / "log", "--key", uri, "--json")
        assert checked.returncode == 0, checked.stderr
        assert json.loads(checked.stdout)["key_id"] == made["key_id"]
    published = cli("publish", tmp_path / "log", "--out", tmp_path / "tlog", "--key",
                    hsm.uri("amr-7", pin=None))  # fmt: skip
    assert published.returncode == 0, published.stderr
    assert (tmp_path / "tlog" / "amr-01" / "checkpoint").is_file()
    vkey = cli("witness", "vkey", "--key", hsm.uri("amr-7", pin=None), "--origin", "o.example/r")
    assert vkey.returncode == 0, vkey.stderr
    raw = load_public_key(hsm.uri("amr-7")).raw
    assert vkey.stdout.strip() == verifier_key("o.example/r", raw)
    # keygen --public-only writes the same .pub again, and makes nothing in the token.
    again = cli("keygen", "--out", tmp_path / "keys", "--token", hsm.uri("amr-7"),
                "--public-only", "--json")  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout)["key_id"] == made["key_id"]
    assert Path(made["public_path"]).read_bytes() == original
    # A .pub there is replaced only with --force (this --force can do what it says).
    public_only = ("keygen", "--out", tmp_path / "keys", "--token", hsm.uri("amr-7"),
                   "--public-only")  # fmt: skip
    one_line(cli(*public_only), 4, "amr-7.pub", "--force")
    assert cli(*public_only, "--force").returncode == 0
    one_line(cli("keygen", "--out", tmp_path, "--public-only"), 2, "--token")
    one_line(cli("verify", tmp_path / "log", "--key", hsm.uri("nobody")), 2,
             "no public key object(s) found")  # fmt: skip


def test_keygen_on_a_key_the_token_holds_does_not_suggest_force(
    hsm: SoftHsm, tmp_path: Path
) -> None:
    """A second keygen of a token key cannot succeed with --force (the token never replaces
    a key), so the refusal says so and points to --public-only, with or without a .pub."""
    keygen = ("keygen", "--out", tmp_path / "keys", "--token", hsm.uri("amr-7"))
    assert cli(*keygen).returncode == 0
    for extra in ((), ("--force",)):
        done = cli(*keygen, *extra)
        one_line(done, 4, "never replaced", "--public-only")
        assert "(--force)" not in done.stderr
    (tmp_path / "keys" / "amr-7.pub").unlink()
    one_line(cli(*keygen), 4, "never replaced", "--public-only")
