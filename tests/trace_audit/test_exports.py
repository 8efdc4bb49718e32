"""``from trace_audit import explain, timeline`` gives the functions, whatever was imported
before: no exported name is also a module or folder at trace_audit's top (the modules are
``explanation`` and ``transitions``), so binding a submodule never shadows an export."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import trace_audit


def test_no_exported_name_is_also_a_submodule() -> None:
    top = Path(trace_audit.__file__).parent
    submodules = {
        p.stem for p in top.iterdir() if p.suffix == ".py" or (p / "__init__.py").is_file()
    }
    assert not set(trace_audit.__all__) & submodules


def test_the_functions_stay_functions_after_their_modules_are_imported() -> None:
    code = (
        "import types\n"
        "import trace_audit.explanation, trace_audit.transitions, trace_audit.incident\n"
        "from trace_audit import explain, timeline, why\n"
        "for f in (explain, timeline, why):\n"
        "    assert isinstance(f, types.FunctionType), f\n"
        "assert explain is trace_audit.explanation.explain\n"
        "assert timeline is trace_audit.transitions.timeline\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
