"""Roots for the compliance tests: a simulator root whose checkpoints are signed and
cosigned by a real ``witness serve`` process, the same robot unsigned, and a root written
by a robot that names no software version; and ``comply``, the CLI run as a user runs it."""

from __future__ import annotations

import dataclasses
import json
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.trace_audit.witness.conftest import Keys, WitnessProcess, run_cli
from trace_runtime.tlog.keys import generate_keypair

ROBOT = "amr-7"  # the origin the witness fixtures name: trace.local/amr-7


@dataclasses.dataclass(frozen=True)
class Comply:
    code: int
    report: dict[str, Any] | None
    stderr: str

    def clause(self, reference: str) -> dict[str, Any]:
        assert self.report is not None, self.stderr
        return next(c for c in self.report["clauses"] if c["reference"] == reference)

    def not_met(self) -> list[str]:
        assert self.report is not None, self.stderr
        return [c["reference"] for c in self.report["clauses"] if c["verdict"] != "met"]

    def failed_checks(self) -> set[str]:
        assert self.report is not None, self.stderr
        return {
            check["check"]
            for clause in self.report["clauses"]
            for check in clause["checks"]
            if check["verdict"] != "met"
        }


def comply(root: Path, profile: str, *args: str) -> Comply:
    """``trace-audit comply ROOT --profile PROFILE ARGS --json`` in a process of its own."""
    done = run_cli("comply", str(root), "--profile", profile, *args, "--json")
    report = json.loads(done.stdout) if done.stdout.strip() else None
    return Comply(done.returncode, report, done.stderr)


@pytest.fixture(scope="session")
def comply_keys(tmp_path_factory: pytest.TempPathFactory) -> Keys:
    folder = tmp_path_factory.mktemp("comply-keys")
    robot = generate_keypair(folder, name=ROBOT)
    witness = generate_keypair(folder, name="witness")
    return Keys(folder, robot.private_path, robot.public_path, witness.private_path,
                witness.public_path)  # fmt: skip


def _sim_root(out: Path, key: Path | None, witness: str | None) -> Path:
    from sim.faults import FaultRates
    from sim.runner import RunConfig, run

    # Declared drops only (audit-write timeouts): a declared gap is logged, not lost.
    faults = dataclasses.replace(FaultRates.off(), audit_write_timeout=0.02)
    run(RunConfig(out=out, scenario="all", cycles=25, seed=7, faults=faults, robot_id=ROBOT,
                  checkpoint_key=key, witness=witness))  # fmt: skip
    return out


@pytest.fixture(scope="session")
def witnessed_root(tmp_path_factory: pytest.TempPathFactory, comply_keys: Keys) -> Iterator[Path]:
    """A simulator root, its checkpoints signed and cosigned by a real witness process."""
    work = tmp_path_factory.mktemp("witnessed")
    witness = WitnessProcess(work / "state", comply_keys, [comply_keys.robot_vkey])
    witness.start()
    try:
        yield _sim_root(work / "root", comply_keys.robot_key, witness.url)
    finally:
        assert witness.stop() == 0


@pytest.fixture(scope="session")
def unsigned_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _sim_root(tmp_path_factory.mktemp("unsigned") / "root", None, None)


@pytest.fixture
def copy_of(tmp_path: Path) -> Any:
    """A copy of a session root that a test may change."""

    def copy(root: Path) -> Path:
        target = tmp_path / f"copy-{len(list(tmp_path.glob('copy-*')))}"
        shutil.copytree(root, target)
        return target

    return copy


def trusted(keys: Keys) -> tuple[str, ...]:
    """The options that give comply the robot's key and the witness's verifier key."""
    return ("--key", str(keys.robot_pub), "--witness-key", keys.witness_verifier.vkey)
