"""Imports run one way: the embeddable runtime stays light, the robot never carries the
investigator, and typer/rich stay inside the CLI modules."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _imports(package: str) -> dict[Path, set[str]]:
    found: dict[Path, set[str]] = {}
    for path in (ROOT / package).rglob("*.py"):
        names: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split(".")[0])
        found[path] = names
    return found


@pytest.mark.parametrize(
    ("package", "banned"),
    [
        ("trace_runtime", {"trace_audit", "sim", "typer", "rich", "networkx", "numpy"}),
        ("sim", {"trace_audit"}),
        ("trace_audit", {"sim"}),
    ],
)
def test_package_does_not_import(package: str, banned: set[str]) -> None:
    offenders = {
        str(path.relative_to(ROOT)): sorted(names & banned)
        for path, names in _imports(package).items()
        if names & banned
    }
    assert not offenders


def test_typer_and_rich_live_only_in_cli_modules() -> None:
    for package in ("trace_audit", "sim"):
        for path, names in _imports(package).items():
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith("trace_audit/cli/") or rel == "sim/cli.py":
                continue
            assert not names & {"typer", "rich"}, rel


def test_the_investigator_package_exports_import_lazily_and_resolve() -> None:
    code = (
        "import sys, trace_audit\n"
        "assert 'networkx' not in sys.modules, 'import trace_audit must stay light'\n"
        "assert sorted(trace_audit.__all__) == sorted(trace_audit._EXPORTS)\n"
        "for name in trace_audit.__all__:\n"
        "    getattr(trace_audit, name)\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
