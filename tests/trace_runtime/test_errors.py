"""The error tree drawn in trace_runtime/errors.py is the tree the classes form: every public
error stands in exactly one of the three branches (usage, input, storage), and the drawing
names each class under its parent."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from trace_runtime import errors
from trace_runtime.errors import InputError, StorageError, TraceError, UsageError

BRANCHES = (UsageError, InputError, StorageError)
PUBLIC = [
    getattr(errors, name)
    for name in errors.__all__
    if name.endswith("Error") and name != "TraceError"
]


@pytest.mark.parametrize("error", PUBLIC, ids=lambda e: e.__name__)
def test_every_public_error_stands_in_exactly_one_branch(error: type[TraceError]) -> None:
    assert issubclass(error, TraceError)
    assert sum(issubclass(error, branch) for branch in BRANCHES) == 1


def test_the_drawing_is_the_tree() -> None:
    """Each name in the docstring's drawing is indented under the class it derives from."""
    doc = errors.__doc__ or ""
    drawn: dict[str, str] = {}
    stack: list[tuple[int, str]] = []
    for line in doc.splitlines():
        found = re.match(r"^[\s│]*(?:[├└]── )?([A-Z]\w*Error)\b", line)
        if not found:
            continue
        depth = found.start(1)
        while stack and stack[-1][0] >= depth:
            stack.pop()
        if stack:
            drawn[found.group(1)] = stack[-1][1]
        stack.append((depth, found.group(1)))
    assert set(drawn) | {"TraceError"} == {n for n in errors.__all__ if n.endswith("Error")}
    for name, parent in drawn.items():
        assert getattr(errors, parent) in getattr(errors, name).__bases__, name


def test_no_other_runtime_module_defines_a_public_error() -> None:
    """The public subclasses live in errors.py; a module may keep a private one (``_Name``)."""
    root = Path(errors.__file__).parent
    elsewhere = [
        f"{path.relative_to(root)}: {name}"
        for path in root.rglob("*.py")
        if path.name != "errors.py"
        for name in re.findall(r"^class ([A-Za-z]\w*Error)\(", path.read_text(), re.M)
    ]
    assert not elsewhere
