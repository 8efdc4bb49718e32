"""docs/api.md runs as written: its ``trace-sim`` commands make the logs, then its Python
blocks run in order in one session in that directory (and so does the README's "Python API"
example, on the same logs), and its table of columns names every column the layer tables
have."""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

ROOT = Path(__file__).resolve().parents[1]
API = ROOT / "docs" / "api.md"
README = ROOT / "README.md"


def _blocks(language: str, text: str | None = None) -> list[str]:
    page = API.read_text() if text is None else text
    return re.findall(rf"^```{language}\n(.*?)^```", page, flags=re.M | re.S)


def _sim_commands() -> list[list[str]]:
    return [
        shlex.split(line)[1:]
        for block in _blocks("sh")
        for line in block.splitlines()
        if line.startswith("trace-sim ")
    ]


@pytest.fixture(scope="module")
def api_logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from evaluation.cli import app

    where = tmp_path_factory.mktemp("api")
    with contextlib.chdir(where):
        for args in _sim_commands():
            made = CliRunner().invoke(app, args)
            assert made.exit_code == 0, (args, made.output)
    return where


def test_the_page_makes_its_logs_and_has_examples() -> None:
    assert len(_sim_commands()) == 4
    assert len(_blocks("python")) >= 6


def test_the_python_examples_run_in_order(api_logs: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("pandas")
    monkeypatch.chdir(api_logs)
    session: dict[str, object] = {}
    out = io.StringIO()
    for number, block in enumerate(_blocks("python"), 1):
        with contextlib.redirect_stdout(out):
            exec(compile(block, f"docs/api.md block {number}", "exec"), session)
    assert "STOP decisions" in out.getvalue()


def test_every_table_column_is_documented() -> None:
    pa = pytest.importorskip("pyarrow")
    from trace_audit import layers

    text = API.read_text()
    for name in ("decision", "entity", "channel", "check", "gap"):
        schema = getattr(layers, f"_{name}_schema")(pa)
        (row,) = [line for line in text.splitlines() if line.startswith(f"| `{name}_table` |")]
        missing = [c for c in schema.names if f"`{c}`" not in row]
        assert not missing, (name, missing)


def test_the_readme_example_runs(api_logs: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("pandas")
    section = README.read_text().split("\n## Python API\n", 1)[1].split("\n## ", 1)[0]
    (block,) = _blocks("python", section)
    monkeypatch.chdir(api_logs)
    session: dict[str, object] = {}
    exec(compile(block, "README.md Python API", "exec"), session)
    assert session["stops"] and session["result"] is not None
