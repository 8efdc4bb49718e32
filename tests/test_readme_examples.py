"""The README's "Investigating" commands run as written on the log the README tells a reader
to make (``trace-sim run --scenario all --cycles 100 --seed 42 --out run.mcap``)."""

from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from trace_audit.cli import app

README = Path(__file__).resolve().parents[1] / "README.md"


def _investigating_commands() -> list[list[str]]:
    text = README.read_text()
    block = text.split("## Investigating", 1)[1].split("```sh", 1)[1].split("```", 1)[0]
    commands = []
    for line in block.splitlines():
        command = line.split("#", 1)[0].strip()
        if command.startswith("trace-audit ") and " run.mcap" in command:
            commands.append(shlex.split(command)[1:])
    return commands


def test_the_readme_names_the_log_to_make_and_the_commands_to_run() -> None:
    assert "--cycles 100 --seed 42 --out run.mcap" in README.read_text()
    assert len(_investigating_commands()) >= 6


@pytest.mark.parametrize("args", _investigating_commands(), ids=lambda a: " ".join(a[:3]))
def test_a_readme_command_runs_on_the_readme_log(
    args: list[str], readme_log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(readme_log)
    done = CliRunner().invoke(app, [*args, "--plain"] if args[0] != "export" else args)
    assert done.exit_code == 0, (args, done.output)
    assert not re.search(r"Traceback", done.output)


@pytest.fixture(scope="module")
def readme_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from sim.cli import app as sim_app

    where = tmp_path_factory.mktemp("readme")
    made = CliRunner().invoke(
        sim_app,
        [
            "run",
            "--scenario",
            "all",
            "--cycles",
            "100",
            "--seed",
            "42",
            "--out",
            str(where / "run.mcap"),
        ],
    )
    assert made.exit_code == 0, made.output
    # A reader runs the commands in the checkout, where the shipped rules files are.
    shutil.copytree(README.parent / "docs" / "rules", where / "docs" / "rules")
    return where


def test_the_readme_stays_a_first_page() -> None:
    """Under 150 lines, and no history or budget table: figures live in docs/performance.md,
    history (commits, issues, earlier runs) in CHANGELOG.md."""
    text = README.read_text()
    assert len(text.splitlines()) < 150
    assert not re.search(r"\bissue \d+|earlier run|this session", text, re.IGNORECASE)
    hashes = set(re.findall(r"\b[0-9a-f]{7,40}\b", text)) - {"ed25519"}
    assert not hashes
    assert "| target |" not in text and "| budget |" not in text
    assert "pip install ." in text and "'.[cli]'" in text
