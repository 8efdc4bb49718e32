"""A root that carries a compliance profile keeps what it asks: ``compact`` and retention
refuse, one line and exit 2, to delete or summarise records younger than its period unless
``--override-compliance``; their defaults rise to the period; a ``compliance.toml`` that
cannot be read refuses compaction (exit 3) instead of letting records go."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from tests.trace_audit.conftest import write_log
from tests.trace_audit.witness.conftest import run_cli


@pytest.fixture
def adopted(tmp_path: Path) -> Path:
    root = write_log(tmp_path / "root")
    done = run_cli("comply", str(root), "--profile", "ai-act-art12", "--adopt", "--json")
    assert done.returncode == 1  # unsigned without --key: adopted all the same
    assert (root / "compliance.toml").is_file()
    return root


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in root.rglob("*") if p.is_file()}


@pytest.mark.parametrize(
    "args",
    [
        ("--tier", "warm", "--older-than", "0", "--include-unfinished"),
        ("--tier", "cold", "--older-than", "0", "--retention", "30d"),
        ("--tier", "cold", "--older-than", "0", "--retention", "183d", "--dry-run"),
    ],
)
def test_compact_refuses_to_delete_younger_records(adopted: Path, args: tuple[str, ...]) -> None:
    before = _files(adopted)
    done = run_cli("compact", str(adopted), *args)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "ai-act-art12" in done.stderr
    assert "184d" in done.stderr and "--override-compliance" in done.stderr
    assert _files(adopted) == before


def test_the_defaults_rise_to_the_period(adopted: Path) -> None:
    done = run_cli("compact", str(adopted), "--tier", "warm", "--include-unfinished", "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["older_than_ns"] == 184 * 86_400 * 10**9
    assert report["retention_ns"] == 184 * 86_400 * 10**9
    assert report["kept_for"] == ["ai-act-art12"] and report["segments"] == []


def test_the_named_flag_overrides(adopted: Path) -> None:
    done = run_cli("compact", str(adopted), "--tier", "warm", "--older-than", "0",
                   "--include-unfinished", "--override-compliance", "--json")  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert [s["status"] for s in json.loads(done.stdout)["segments"]] == ["compacted"]


def test_a_root_without_a_profile_compacts_as_before(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root")
    done = run_cli("compact", str(root), "--tier", "warm", "--older-than", "0",
                   "--include-unfinished", "--json")  # fmt: skip
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["retention_ns"] == 183 * 86_400 * 10**9 and report["kept_for"] == []


@pytest.mark.parametrize("damage", ["garbage", "fifo", "bool_days"])
def test_an_unreadable_compliance_file_refuses_compaction(adopted: Path, damage: str) -> None:
    path = adopted / "compliance.toml"
    path.unlink()
    if damage == "fifo":
        os.mkfifo(path)
    elif damage == "garbage":
        path.write_text("[[profile]\nname = ")
    else:
        path.write_text('[[profile]]\nname = "x"\nkeep_days = true\n')
    done = run_cli("compact", str(adopted), "--tier", "warm", "--older-than", "0",
                   "--include-unfinished", "--override-compliance", timeout=60)  # fmt: skip
    assert done.returncode == 3, done.stderr
    assert done.stderr.count("\n") == 1 and "compliance.toml" in done.stderr
