"""``trace-audit verify`` and ``keygen``: what they print, in text and JSON, and how they exit.

What the verification finds is pinned in tests/trace_runtime/verification/.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

from typer.testing import CliRunner

from tests.trace_audit.profile_writer import Faults, write_profile_log
from tests.trace_runtime.verification.test_tamper import (
    decode,
    flip_byte,
    write,
    write_signed_log,
)
from trace_audit.cli import app
from trace_audit.verify import verify_log
from trace_runtime.tlog.keys import Ed25519Signer, generate_keypair, load_signer


def test_a_clock_stepping_back_within_a_segment_is_a_note_that_names_the_cycle(
    tmp_path: Path,
) -> None:
    """The chain is intact, so it is not tampering; but PROFILE section 4 forbids it, and an
    investigator asking "what happened at t" must know that t is ambiguous in that segment."""
    log = write_profile_log(tmp_path / "p.mcap", faults=Faults(clock_step_back_at=12))
    report = verify_log(log)
    assert report.ok and report.findings == []
    (note,) = [n for n in report.notes if n.kind == "clock_backwards"]
    assert (note.where.first_cycle, note.where.last_cycle) == (12, 12)
    assert "0.150 s earlier than cycle 11" in note.message
    assert "section 4" in note.message
    plain = CliRunner().invoke(app, ["verify", str(log), "--plain"])
    assert plain.exit_code == 0 and "backwards" in plain.output


# --- the command line ---------------------------------------------------------------------

runner = CliRunner()


def _run(*args: str) -> tuple[int, str, str]:
    result = runner.invoke(app, list(args))
    return result.exit_code, result.stdout, result.stderr


def test_cli_verify_clean_prints_the_range_and_exits_0(sample_log: Path) -> None:
    code, out, err = _run("verify", str(sample_log), "--plain")
    assert code == 0, err
    assert "CLEAN" in out and "cycles 0..99" in out and "t = 100.000 s .. 109.900 s" in out
    assert "anchored" in out and "through cycle 99" in out
    assert "not checked (no --key)" in out


def test_cli_verify_with_a_key_and_json(tmp_path: Path) -> None:
    keys = generate_keypair(tmp_path / "keys")
    path = write_signed_log(tmp_path / "run.mcap", load_signer(keys.private_path), 25)
    code, out, err = _run("verify", str(path), "--key", str(keys.public_path), "--json")
    assert code == 0, err
    data = json.loads(out)
    assert data["ok"] is True and data["findings"] == [] and data["key_id"] == keys.key_id
    assert data["robots"][0]["anchored_cycle"] == 24 and data["cycles_valid"] == 25


def test_cli_verify_findings_exit_1_and_are_located(tmp_path: Path) -> None:
    signer = Ed25519Signer.generate()
    path = write_signed_log(tmp_path / "run.mcap", signer, 30)
    decoded = decode(path)
    expect = flip_byte(decoded, random.Random(3), signer)
    write(decoded, path, random.Random(3))
    (tmp_path / "robot.pub").write_bytes(signer.public_key.raw)
    code, out, _err = _run("verify", str(path), "--key", str(tmp_path / "robot.pub"), "--plain")
    assert code == 1
    assert "FINDING" in out and "Findings" in out and str(expect.cycle) in out
    code, out, _err = _run("verify", str(path), "--key", str(tmp_path / "robot.pub"), "--json")
    data = json.loads(out)
    assert code == 1 and data["ok"] is False
    assert any(
        f["first_cycle"] <= expect.cycle <= (f["last_cycle"] or f["first_cycle"])
        for f in data["findings"]
        if f["first_cycle"] is not None
    )


def test_cli_verify_unreadable_input_exits_3(tmp_path: Path) -> None:
    code, _out, err = _run("verify", str(tmp_path / "nope.mcap"))
    assert code == 3 and err.startswith("trace-audit: ") and len(err.splitlines()) == 1
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file at all")
    code, _out, err = _run("verify", str(junk))
    assert code == 3 and "not an MCAP file" in err


def test_cli_verify_bad_key_is_a_usage_error(sample_log: Path, tmp_path: Path) -> None:
    (tmp_path / "bad.pub").write_text("hello\n")
    code, _out, err = _run("verify", str(sample_log), "--key", str(tmp_path / "bad.pub"))
    assert code == 2 and "public key" in err and len(err.splitlines()) == 1


def test_cli_keygen_writes_a_key_pair_and_refuses_to_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "keys"
    code, stdout, err = _run("keygen", "--out", str(out), "--name", "amr-7", "--plain")
    assert code == 0, err
    assert (out / "amr-7.key").exists() and (out / "amr-7.pub").exists()
    assert "trace-audit verify LOG --key" in stdout
    code, _stdout, err = _run("keygen", "--out", str(out), "--name", "amr-7")
    assert code == 4 and "refusing to overwrite" in err
    code, stdout, err = _run("keygen", "--out", str(out), "--name", "amr-7", "--force", "--json")
    assert code == 0 and len(json.loads(stdout)["key_id"]) == 64


def test_every_integrity_command_has_help_with_an_example() -> None:
    for command in ("verify", "keygen"):
        code, out, _err = _run(command, "--help")
        assert code == 0 and "Examples" in out and f"trace-audit {command}" in out
