"""``trace-audit comply`` from outside: a signed, witnessed simulator root conforms to both
shipped profiles; an unsigned root and a root whose robot names no software version each
fail, naming the clause on stderr and in the JSON (every clause listed with its verdict)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from tests.trace_audit.comply.conftest import comply, trusted
from tests.trace_audit.conftest import write_log
from tests.trace_audit.witness.conftest import Keys
from trace_audit.comply import SHIPPED, load_profile


def test_a_signed_witnessed_simulator_root_conforms_to_both_profiles(
    witnessed_root: Path, comply_keys: Keys, copy_of: Callable[[Path], Path]
) -> None:
    root = copy_of(witnessed_root)
    for profile in SHIPPED:
        done = comply(root, profile, *trusted(comply_keys), "--adopt")
        assert done.code == 0, done.stderr
        assert done.report is not None and done.report["conforms"] is True
        listed = [c["reference"] for c in done.report["clauses"]]
        assert listed == [c.reference for c in load_profile(profile).clauses]
        assert all(c["verdict"] == "met" for c in done.report["clauses"])
        assert done.stderr == ""
    adopted = (root / "compliance.toml").read_text()
    assert 'name = "machinery-2023-1230"' in adopted and 'name = "ai-act-art12"' in adopted


def test_the_simulator_root_shows_its_version_and_declared_drops_as_evidence(
    witnessed_root: Path, comply_keys: Keys
) -> None:
    done = comply(witnessed_root, "ai-act-art12", *trusted(comply_keys))
    versions = done.clause("Art. 12(2)(a)")["checks"][0]
    assert versions["check"] == "versions" and versions["verdict"] == "met"
    assert any("'trace-sim 0.1'" in line and "'fig2-v2'" in line for line in versions["evidence"])
    gaps = next(c for c in done.clause("Art. 12(1)")["checks"] if c["check"] == "gaps")
    assert gaps["verdict"] == "met"
    # the audit-write timeouts of the run are declared gaps, not lost records
    assert "0 cycles declared dropped" not in gaps["evidence"][0]


def test_an_unsigned_root_fails_naming_the_clause(unsigned_root: Path, comply_keys: Keys) -> None:
    machinery = comply(unsigned_root, "machinery-2023-1230", *trusted(comply_keys))
    assert machinery.code == 1
    assert "Annex III Part B 1.1.9" in machinery.not_met()
    assert {"signed", "witnessed"} <= machinery.failed_checks()
    assert "machinery-2023-1230 Annex III Part B 1.1.9 not met: signed" in machinery.stderr
    ai_act = comply(unsigned_root, "ai-act-art12", "--key", str(comply_keys.robot_pub))
    assert ai_act.code == 1
    assert "Art. 12(1)" in ai_act.not_met()
    assert "ai-act-art12 Art. 12(1) not met: " in ai_act.stderr


def test_a_root_whose_robot_names_no_software_version_fails_naming_the_clause(
    tmp_path: Path,
) -> None:
    root = write_log(tmp_path / "root")  # AuditLogger without software_version
    for profile, reference in (
        ("machinery-2023-1230", "Annex III Part B 1.2.1(f)"),
        ("ai-act-art12", "Art. 12(2)(a)"),
    ):
        done = comply(root, profile)
        assert done.code == 1 and reference in done.not_met()
        versions = next(c for c in done.clause(reference)["checks"] if c["check"] == "versions")
        assert versions["verdict"] == "not met"
        assert "name no software and no policy version" in versions["evidence"][0]
        assert "software_version" in versions["fix"]
        assert f"{reference} not met: versions" in done.stderr


def test_a_bad_profile_is_a_usage_error_before_the_root_is_read(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[[clause]]\nreference = "Art. 1"\nsummary = "s"\n'
                   'checks = ["chain", "telepathy"]\n')  # fmt: skip
    done = comply(tmp_path / "no-such-root", str(bad))
    assert done.code == 2 and done.report is None
    assert done.stderr.count("\n") == 1 and "unknown check 'telepathy'" in done.stderr
    missing = comply(tmp_path, "no-such-profile")
    assert missing.code == 2 and "shipped: machinery-2023-1230, ai-act-art12" in missing.stderr


def test_a_users_own_profile_file_is_read(witnessed_root: Path, tmp_path: Path) -> None:
    own = tmp_path / "own.toml"
    own.write_text('name = "own"\n[[clause]]\nreference = "House rule 1"\n'
                   'summary = "the chain verifies"\nchecks = ["chain", "gaps"]\n')  # fmt: skip
    done = comply(witnessed_root, str(own))
    assert done.code == 0, done.stderr
    assert done.report is not None and done.report["profile"] == "own"
