"""``boundary.write_new``: a file written whole under a name nothing holds, never over one."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from trace_runtime.boundary import write_new
from trace_runtime.errors import StorageError


def test_a_new_name_gets_the_bytes_and_no_partial_is_left(tmp_path: Path) -> None:
    target = tmp_path / "bundle.json"
    write_new(target, b"{}\n")
    assert target.read_bytes() == b"{}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bundle.json"]


@pytest.mark.parametrize("holder", ["file", "link", "dangling link", "folder"])
def test_a_held_name_is_never_replaced(tmp_path: Path, holder: str) -> None:
    target = tmp_path / "bundle.json"
    other = tmp_path / "other"
    other.write_bytes(b"keep")
    if holder == "file":
        target.write_bytes(b"keep")
    elif holder == "link":
        target.symlink_to(other)
    elif holder == "dangling link":
        target.symlink_to(tmp_path / "nothing")
    else:
        target.mkdir()
    with pytest.raises(StorageError, match="never overwritten"):
        write_new(target, b"new")
    assert other.read_bytes() == b"keep"
    if holder == "file":
        assert target.read_bytes() == b"keep"
    assert os.path.lexists(target)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".partial")]
