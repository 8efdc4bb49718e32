"""Imports run one way: the embeddable runtime stays light, the robot never carries the
investigator, and typer/rich stay inside the CLI modules."""

from __future__ import annotations

import ast
import re
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
        (
            "trace_runtime",
            {"trace_audit", "sim", "evaluation", "typer", "rich", "networkx", "numpy"},
        ),
        ("sim", {"trace_audit", "evaluation"}),
        ("trace_audit", {"sim", "evaluation"}),
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
    for package in ("trace_audit", "sim", "evaluation"):
        for path, names in _imports(package).items():
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith("trace_audit/cli/") or rel in {"sim/cli.py", "evaluation/cli.py"}:
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


def test_the_runtime_package_exports_import_lazily_and_resolve() -> None:
    """``import trace_runtime.errors`` (all the CLI needs to start) builds no pydantic
    models; every name in ``__all__`` still resolves on first use."""
    code = (
        "import sys, trace_runtime.errors\n"
        "assert 'pydantic' not in sys.modules, 'import trace_runtime.errors must stay light'\n"
        "assert 'trace_runtime.records' not in sys.modules\n"
        "import trace_runtime\n"
        "assert sorted(trace_runtime.__all__) == sorted(trace_runtime._EXPORTS)\n"
        "assert sorted(dir(trace_runtime)) == sorted(trace_runtime.__all__)\n"
        "for name in trace_runtime.__all__:\n"
        "    getattr(trace_runtime, name)\n"
        "try:\n"
        "    trace_runtime.nope\n"
        "except AttributeError:\n"
        "    pass\n"
        "else:\n"
        "    raise AssertionError('unknown names must raise AttributeError')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def _module_imports(package: str) -> dict[str, set[str]]:
    """Imports between modules of ``package``, deferred ones (inside functions, or by
    ``importlib.import_module("...")``) included: a cycle through a deferred import is still
    a cycle. ``if TYPE_CHECKING:`` blocks are left out: they never run. ``from pkg import
    mod`` counts as importing ``pkg.mod`` when that is a module."""
    paths = list((ROOT / package).rglob("*.py"))
    modules = {_module_name(path) for path in paths}
    graph: dict[str, set[str]] = {}
    for path in paths:
        tree = ast.parse(path.read_text())
        type_only = {
            id(inner)
            for node in ast.walk(tree)
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
            for inner in ast.walk(node)
        }
        targets: set[str] = set()
        for node in ast.walk(tree):
            if id(node) in type_only:
                continue
            if isinstance(node, ast.Import):
                targets |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                submodules = {f"{node.module}.{alias.name}" for alias in node.names} & modules
                targets |= submodules or {node.module}
            elif (
                isinstance(node, ast.Call)
                and ast.unparse(node.func).endswith("import_module")
                and node.args
                and isinstance(node.args[0], ast.Constant)
            ):
                targets.add(str(node.args[0].value))
        name = _module_name(path)
        graph[name] = {t for t in targets if t in modules and t != name}
    return graph


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    return ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)


@pytest.mark.parametrize("package", ["trace_runtime", "trace_audit", "sim", "evaluation"])
def test_no_import_cycles_inside_a_package(package: str) -> None:
    """A cycle (the reader and the tiers importing each other, filled by side effects) makes
    import order matter; the layers must only ever import downwards."""
    graph = _module_imports(package)
    state: dict[str, int] = {}
    cycles: list[list[str]] = []

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append([*path[path.index(nxt) :], nxt])
            elif nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    assert not cycles


FLOORS: dict[str, list[set[str]]] = {
    # docs/architecture.md draws these floors; a module imports from its own floor or below.
    "trace_runtime": [
        # the ground: records, errors and the rules every reader and writer shares
        {
            "errors", "lazy", "costs", "clock", "flags", "segment_names", "read_limits",
            "gaps", "record_model", "recording_records", "records", "session", "schemas",
            "chain", "boundary",
            "live_writers",
        },
        # a record's bytes and an MCAP file's bytes, cycles assembled by the chain
        {"encoding"},
        # the Merkle tree, signed notes, keys, checkpoints, the witness client and store
        {"tlog"},
        # the warm and cold tier formats, read by the reader
        {"tier_formats"},
        # one segment, a robot's recordings, a log of many files, a robot's tree
        {"reading"},
        # the logger a robot embeds
        {"logger"},
        # the recorder service: robots in other languages feed the same logger over a socket
        {"recorder"},
        {"verification"},
        # moving segments between tiers verifies every copy it makes
        {"tiers"},
        {"", "testing"},  # the package's face, and the test double users test their robots with
    ],
    "trace_audit": [
        # what every question needs: times, sources, a cycle's fields, JSON, evidence, columns
        {
            "jsonout", "log_time", "selection", "log_source", "cycle_fields", "log_gaps",
            "sensor_window", "evidence", "readings", "columns",
        },
        # views over one decision: its causal graph, its chains, what it knew of its sensors
        {"causal", "chains", "sensor_health"},
        # the questions an investigator asks of a log
        {"metrics", "explanation", "export", "transitions", "info", "verify", "doctor", "layers"}
        | {"rules", "tail", "witness", "proof", "proof_data", "proof_readings"}
        | {"publish"}
        | {"key_chain", "proof_keys"},
        # what is built from the answers: the fleet index, the incident report, the Foxglove view
        {"fleet", "incident", "foxglove", "comply"},
        # entry: the console script's check that the cli extra is installed; assistant: the
        # MCP server, the CLI's sibling face (it asks the questions as the commands' --json does)
        {"cli", "entry", "assistant"},
        {""},
    ],
}  # fmt: skip


def _floor_of(package: str, module: str) -> int | None:
    inside = module.removeprefix(package).removeprefix(".")
    for floor, names in enumerate(FLOORS[package]):
        if inside in names or inside.split(".")[0] in names - {""}:
            return floor
    return None


@pytest.mark.parametrize("package", sorted(FLOORS))
def test_every_module_stands_on_a_floor(package: str) -> None:
    """A new module is given its floor on purpose, in FLOORS and in docs/architecture.md."""
    unplaced = sorted(m for m in _module_imports(package) if _floor_of(package, m) is None)
    assert not unplaced


@pytest.mark.parametrize("package", sorted(FLOORS))
def test_no_module_imports_from_a_higher_floor(package: str) -> None:
    upward = sorted(
        (module, target)
        for module, targets in _module_imports(package).items()
        for target in targets
        if (_floor_of(package, target) or 0) > (_floor_of(package, module) or 0)
    )
    assert not upward


def test_the_reader_layers_import_downwards() -> None:
    """Bytes, then cycles, then one segment, then many: never the other way."""
    graph = _module_imports("trace_runtime")
    assert "trace_runtime.reading.reader" not in graph["trace_runtime.encoding.mcap_file"]
    assert "trace_runtime.reading.logset" not in graph["trace_runtime.reading.reader"]
    assert not graph["trace_runtime.encoding.cycles"] & {
        "trace_runtime.encoding.mcap_file",
        "trace_runtime.reading.reader",
        "trace_runtime.reading.logset",
    }


def test_the_tier_formats_sit_below_the_reader_and_compaction_above_verification() -> None:
    """The warm and cold formats are read by the reader, so they import nothing that reads
    segments; writing, recovering and retiring tiers verify, so they sit above it."""
    graph = _module_imports("trace_runtime")
    above_the_formats = {
        "trace_runtime.reading.reader",
        "trace_runtime.reading.logset",
        "trace_runtime.verification",
        "trace_runtime.tiers",
    }
    for module, targets in graph.items():
        if module.startswith("trace_runtime.tier_formats"):
            upward = {t for t in targets if any(t.startswith(a) for a in above_the_formats)}
            assert not upward, (module, sorted(upward))
    for module in (
        "trace_runtime.reading.reader",
        "trace_runtime.reading.logset",
        "trace_runtime.verification",
    ):
        assert not {t for t in graph[module] if t.startswith("trace_runtime.tiers")}, module


def _page_floors(package: str) -> list[tuple[set[str], str]]:
    """docs/architecture.md's floor table of ``package``: per row, the top-level names its
    "modules" column gives (``name`` or ``folder/``) and the whole row's text."""
    page = (ROOT / "docs" / "architecture.md").read_text()
    section = page.split(f"## {package}, floor by floor", 1)[1].split("\n## ", 1)[0]
    rows: list[tuple[set[str], str]] = []
    for line in section.splitlines():
        cells = line.split(" | ")
        if not line.startswith("| ") or len(cells) < 3 or cells[0] == "| floor":
            continue
        column = cells[1].split(":", 1)[0] if "/`:" in cells[1] else cells[1]
        rows.append(({n.rstrip("/") for n in re.findall(r"`([^`]+)`", column)}, line))
    return rows


def _top_level(package: str) -> set[str]:
    base = ROOT / package
    return {
        p.stem if p.is_file() else p.name
        for p in base.iterdir()
        if (p.suffix == ".py" and p.stem != "__init__") or (p / "__init__.py").is_file()
    }


@pytest.mark.parametrize("package", sorted(FLOORS))
def test_the_architecture_page_draws_the_floors(package: str) -> None:
    """Every module and folder at the package's top is on the page, on the floor FLOORS gives
    it, and the page names nothing the package lacks."""
    rows = _page_floors(package)
    declared = [names - {""} for names in FLOORS[package] if names - {""}]
    assert [names for names, _ in rows] == declared
    assert set().union(*declared) == _top_level(package)


def test_the_architecture_page_names_every_module_of_each_runtime_folder() -> None:
    rows = dict((frozenset(names), text) for names, text in _page_floors("trace_runtime"))
    for names, text in rows.items():
        for folder in names:
            base = ROOT / "trace_runtime" / folder
            if not base.is_dir():
                continue
            modules = {p.stem for p in base.rglob("*.py") if p.stem != "__init__"}
            modules |= {p.name for p in base.iterdir() if (p / "__init__.py").is_file()}
            missing = sorted(m for m in modules if f"`{m}`" not in text and f"{m}/" not in text)
            assert not missing, (folder, missing)


def test_the_runtime_ground_stays_small() -> None:
    """The top of trace_runtime is the ground: at most 20 modules; every floor above is a
    folder."""
    ground = FLOORS["trace_runtime"][0]
    assert len(ground) <= 20
    for names in FLOORS["trace_runtime"][1:-1]:
        assert all((ROOT / "trace_runtime" / name).is_dir() for name in names), names
