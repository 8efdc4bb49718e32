"""A robot installs the logger alone: ``pip install .`` (no extras) brings what
``trace_runtime`` imports and nothing of the investigator; ``trace-audit`` and ``trace-sim``
without the ``cli`` extra say in one line how to get it and exit 5 (docs/cli.md).

The metadata tests read pyproject.toml and this environment's installed distributions; the
last test installs the checkout into a fresh virtual environment from the package index
(about 20 s) and skips, saying why, when the index is out of reach."""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest

from trace_audit.entry import INVESTIGATOR_MODULES
from trace_runtime.errors import EXIT_NOT_INSTALLED

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]

BANNED = {"typer", "rich", "networkx", "numpy", "pyarrow", "duckdb", "matplotlib", "dask", "rtamt"}
"""DESIGN.md: what a robot's install never carries."""

NOT_INSTALLED = re.compile(
    r"^(trace-audit|trace-sim): the investigator is not installed in this environment"
    r" \(no [a-z, ]+\): pip install 'trace-audit\[cli\]' \(from a checkout: pip install"
    r" '\.\[cli\]'\)\n$"
)


def _dist(requirement: str) -> str:
    """The normalized distribution name of a requirement string (PEP 503)."""
    match = re.match(r"[A-Za-z0-9._-]+", requirement)
    assert match, requirement
    return _normalized(match.group())


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _core() -> set[str]:
    return {_dist(r) for r in PYPROJECT["dependencies"]}


def _extra(name: str) -> set[str]:
    return {_dist(r) for r in PYPROJECT["optional-dependencies"][name]}


def _third_party_imports(package: str) -> dict[str, set[str]]:
    """Top-level modules imported anywhere in ``package`` (inside functions too), outside
    ``if TYPE_CHECKING:`` blocks (they never run), that are neither the standard library nor
    the project's own: module name -> the files importing it."""
    own = {"trace_runtime", "trace_audit", "sim", "evaluation"}
    found: dict[str, set[str]] = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        tree = ast.parse(path.read_text())
        type_only = {
            id(inner)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
            for inner in ast.walk(node)
        }
        for node in ast.walk(tree):
            if id(node) in type_only:
                continue
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in own:
                    found.setdefault(top, set()).add(str(path.relative_to(ROOT)))
    return found


# extras a robot installs beside the runtime: they must not bring the investigator
ROBOT_EXTRAS = {"token"}


def test_every_module_the_runtime_imports_comes_with_a_core_dependency() -> None:
    """Each third-party import in trace_runtime/ is provided (per the installed
    distributions' records) by a distribution pyproject.toml lists as a core dependency, or
    by a robot's extra and then imported in the one module that needs it (python-pkcs11 in
    ``tlog/pkcs11_session.py``, only when a key is a ``pkcs11:`` URI). The cold codec imports no
    numpy."""
    imports = _third_party_imports("trace_runtime")
    assert {"mcap", "pydantic", "zstandard", "lz4", "orjson", "msgspec", "cryptography"} <= set(
        imports
    )
    providers = packages_distributions()
    core = _core()
    robot_extra = {dist for name in ROBOT_EXTRAS for dist in _extra(name)}
    unprovided = {
        module: sorted(files)
        for module, files in imports.items()
        if not {_normalized(d) for d in providers.get(module, [])} & core
    }
    assert unprovided == {"pkcs11": ["trace_runtime/tlog/pkcs11_session.py"]}
    assert {_normalized(d) for d in providers["pkcs11"]} <= robot_extra


def test_no_investigator_package_is_a_core_dependency() -> None:
    assert not _core() & BANNED
    assert {"typer", "rich", "networkx", "numpy"} <= _extra("cli")


def test_the_entry_check_looks_for_exactly_what_the_cli_extra_brings() -> None:
    providers = packages_distributions()
    checked = {_normalized(d) for m in INVESTIGATOR_MODULES for d in providers[m]}
    assert checked == _extra("cli")


def test_all_is_every_extra_but_dev_and_each_investigator_extra_brings_cli() -> None:
    extras = PYPROJECT["optional-dependencies"]
    (everything,) = extras["all"]
    assert everything.startswith("trace-audit[")
    named = set(everything.removeprefix("trace-audit[").removesuffix("]").split(","))
    assert named == set(extras) - {"all", "dev"}
    for name in named - {"cli"} - ROBOT_EXTRAS:
        assert "trace-audit[cli]" in extras[name], name
    for name in ROBOT_EXTRAS:
        assert not any(dep.startswith("trace-audit[") for dep in extras[name]), name


def test_the_console_scripts_start_with_the_check() -> None:
    """The investigator's programs start with the extra's check; the recorder is part of a
    robot's install and needs none."""
    assert PYPROJECT["scripts"] == {
        "trace-audit": "trace_audit.entry:main",
        "trace-sim": "evaluation.entry:main",
        "trace-recorder": "trace_runtime.recorder.cli:main",
    }


def _run_entry(
    entry: str, args: list[str], hidden: str | None = None
) -> subprocess.CompletedProcess[str]:
    """The console script ``entry`` as a process, with the module ``hidden`` made
    unimportable, as in an environment that lacks it."""
    prog = "trace-audit" if entry.startswith("trace_audit") else "trace-sim"
    module, function = entry.split(":")
    code = (
        "import sys\n"
        + (f"sys.modules[{hidden!r}] = None\n" if hidden else "")
        + f"sys.argv = [{prog!r}, *{args!r}]\n"
        + f"from {module} import {function}\n"
        + f"{function}()\n"
    )
    env = {**os.environ, "COLUMNS": "100", "TERM": "dumb", "NO_COLOR": "1"}
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=False,
    )


@pytest.mark.parametrize(
    ("entry", "hidden"),
    [("trace_audit.entry:main", "typer"), ("evaluation.entry:main", "numpy")],
)
def test_without_the_extra_a_command_says_in_one_line_how_to_get_it(
    entry: str, hidden: str
) -> None:
    done = _run_entry(entry, ["--help"], hidden)
    assert done.returncode == EXIT_NOT_INSTALLED
    assert done.stdout == ""
    assert NOT_INSTALLED.match(done.stderr), done.stderr
    assert f"(no {hidden})" in done.stderr


@pytest.mark.parametrize(
    ("entry", "program"),
    [
        ("trace_audit.entry:main", "trace_audit.cli:main"),
        ("evaluation.entry:main", "evaluation.cli:main"),
    ],
)
def test_with_the_extra_the_check_hands_over_unchanged(entry: str, program: str) -> None:
    """The same help, byte for byte, and the same exit code as the program called directly."""
    for args in (["--help"], ["--no-such-option"]):
        through, direct = _run_entry(entry, args), _run_entry(program, args)
        assert (through.returncode, through.stdout, through.stderr) == (
            direct.returncode,
            direct.stdout,
            direct.stderr,
        )


def _source_copy(dest: Path) -> Path:
    """What ``pip install .`` builds from, copied, so the build writes nothing into the
    checkout (setuptools leaves build/ and *.egg-info beside the sources)."""
    dest.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, dest / name)
    for package in ("trace_runtime", "trace_audit", "sim", "evaluation"):
        shutil.copytree(
            ROOT / package, dest / package, ignore=shutil.ignore_patterns("__pycache__")
        )
    return dest


def _run(args: list[str], cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    # The fresh environment must not see this checkout or this venv through PYTHONPATH.
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "PYTHONHOME"}}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return subprocess.run(
        args, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env, check=False
    )


@pytest.mark.slow
def test_a_robot_install_logs_reads_and_verifies_without_the_investigator(tmp_path: Path) -> None:
    """``pip install .`` into a new virtual environment: the example robot writes a log that
    the runtime reads back and verifies; none of the investigator's packages is installed;
    ``trace-audit`` and ``trace-sim`` each print the one line and exit 5."""
    venv = tmp_path / "robot-venv"
    made = _run([sys.executable, "-m", "venv", str(venv)], tmp_path)
    assert made.returncode == 0, made.stderr
    python, bin_dir = venv / "bin" / "python", venv / "bin"
    probe = _run(
        [str(python), "-m", "pip", "download", "--no-deps", "-d", str(tmp_path / "probe"), "mcap"],
        tmp_path,
    )
    if probe.returncode != 0:
        last = (probe.stderr.strip().splitlines() or ["no output"])[-1]
        pytest.skip(f"the package index is out of reach, so nothing can be installed: {last}")

    source = _source_copy(tmp_path / "checkout")
    installed = _run([str(python), "-m", "pip", "install", str(source)], tmp_path, timeout=600)
    assert installed.returncode == 0, installed.stdout[-3000:] + installed.stderr[-3000:]

    listed = _run([str(python), "-m", "pip", "list", "--format=json"], tmp_path)
    names = {_normalized(row["name"]) for row in json.loads(listed.stdout)}
    assert not names & BANNED
    assert _core() | {"trace-audit"} <= names

    log = tmp_path / "robot.mcap"
    robot = _run(
        [str(python), str(ROOT / "examples" / "minimal_robot.py"), "--out", str(log)], tmp_path
    )
    assert robot.returncode == 0, robot.stderr
    read_back = _run(
        [
            str(python),
            "-c",
            "import sys\n"
            "from trace_runtime import open_log\n"
            "from trace_runtime.verification import verify\n"
            f"log = open_log({str(log)!r})\n"
            "report = verify(log)\n"
            "print(sum(1 for _ in log.iter_cycles()), report.ok, report.cycles_valid)\n",
        ],
        tmp_path,
    )
    assert read_back.returncode == 0, read_back.stderr
    assert read_back.stdout.split() == ["50", "True", "50"]

    # The recorder is the robot's too: it runs without the investigator.
    recorder = _run([str(bin_dir / "trace-recorder"), "serve", "--help"], tmp_path)
    assert recorder.returncode == 0, recorder.stderr
    assert "--socket" in recorder.stdout

    for program in ("trace-audit", "trace-sim"):
        done = _run([str(bin_dir / program), "--help"], tmp_path)
        assert done.returncode == EXIT_NOT_INSTALLED, done.stderr
        assert done.stdout == ""
        assert NOT_INSTALLED.match(done.stderr), done.stderr
        assert done.stderr.startswith(f"{program}: ")
