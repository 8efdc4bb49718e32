"""What ``prove`` and ``verify-proof`` say when they refuse (found from outside): the format a
bundle has and the ones read, the leaf a proof fails for, a proof whose last newline is
gone, and the robots of a root when none (or an unknown one) is named. Bundles are crafted
from a real one as JSON text, the way an outside tester edits them."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.witness.conftest import Keys
from tests.trace_audit.witness.test_tail import write


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory, keys: Keys) -> Path:
    """A root of two signed robots, amr-7 and amr-8."""
    root = tmp_path_factory.mktemp("fleet") / "root"
    write(root, keys.robot_key, range(60))
    write(root, keys.robot_key, range(60), robot_id="amr-8")
    return root


@pytest.fixture(scope="module")
def bundle(fleet: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("bundle") / "cycle-37.json"
    made = cli("prove", fleet, "--cycle", "37", "--robot", "amr-7", "--out", out)
    assert made.returncode == 0, made.stderr
    value: dict[str, Any] = json.loads(out.read_text())
    return value


def _verify(tmp_path: Path, keys: Keys, data: dict[str, Any]) -> Any:
    path = tmp_path / "crafted.json"
    path.write_text(json.dumps(data))
    return cli("verify-proof", path, "--key", keys.robot_pub, "--json")


def test_prove_on_a_fleet_without_robot_names_its_robots(fleet: Path, tmp_path: Path) -> None:
    done = cli("prove", fleet, "--cycle", "37", "--out", tmp_path / "p.json")
    one_line(done, 2, "holds 2 robots (amr-7, amr-8)", "--robot")
    unknown = cli("prove", fleet, "--cycle", "37", "--robot", "amr-9", "--out", tmp_path / "p.json")
    one_line(unknown, 2, "no robot amr-9", "it holds amr-7, amr-8")
    assert not (tmp_path / "p.json").exists()


def test_a_bundle_of_an_unknown_format_names_it_and_the_ones_read(
    bundle: dict[str, Any], keys: Keys, tmp_path: Path
) -> None:
    done = _verify(tmp_path, keys, {**bundle, "format": "trace-proof/9"})
    one_line(done, 3, 'its format is "trace-proof/9"', "trace-proof/1", "trace-proof/5")
    unnamed = _verify(tmp_path, keys, {k: v for k, v in bundle.items() if k != "format"})
    one_line(unnamed, 3, "it has no format field", "trace-proof/5")
    odd = _verify(tmp_path, keys, {**bundle, "format": ["x" * 200, "\n"]})
    one_line(odd, 3, 'its format is ["xxx', "...", "trace-proof/5")
    assert len(odd.stderr) < 400


def test_an_inclusion_that_fails_names_the_leaf(
    bundle: dict[str, Any], keys: Keys, tmp_path: Path
) -> None:
    proof = bundle["tlog_proof"].replace("\nindex 37\n", "\nindex 36\n")
    assert proof != bundle["tlog_proof"]
    done = _verify(tmp_path, keys, {**bundle, "leaf_index": 36, "tlog_proof": proof})
    assert done.returncode == 1, done.stderr
    steps = {name: (ok, detail) for name, ok, detail in json.loads(done.stdout)["steps"]}
    tree = f"leaf 36 of the tree of {bundle['tree_size']} at that root"
    assert steps["inclusion"] == (False, f"the seal is not {tree}")


def test_a_proof_without_its_last_newline_says_so(
    bundle: dict[str, Any], keys: Keys, tmp_path: Path
) -> None:
    assert _verify(tmp_path, keys, bundle).returncode == 0  # the bundle as made verifies
    cut = bundle["tlog_proof"]
    assert cut.endswith("\n") and not cut.endswith("\n\n")
    done = _verify(tmp_path, keys, {**bundle, "tlog_proof": cut[:-1]})
    assert done.returncode == 1, done.stderr
    [(name, ok, detail)] = [s for s in json.loads(done.stdout)["steps"] if not s[1]]
    assert (name, ok) == ("bundle", False)
    assert detail.startswith("the tlog-proof does not end with a newline"), detail
