"""A name a model gives is a path under a configured root, or it is refused; a log's
fingerprint changes when its files do."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from trace_audit.assistant.roots import Roots, fingerprint
from trace_runtime.errors import UnsafePathError, UsageError


@pytest.fixture
def two(tmp_path: Path) -> tuple[Roots, Path, Path]:
    first, second = tmp_path / "first", tmp_path / "second"
    (first / "amr-7").mkdir(parents=True)
    (second / "amr-9" / "hot").mkdir(parents=True)
    (second / "amr-9" / "hot" / "x.mcap").write_bytes(b"not a log, a name")
    (tmp_path / "elsewhere").mkdir()
    (first / "out").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    return Roots.of([first, second]), first, second


def test_a_name_is_found_in_the_first_root_that_holds_it(two: tuple[Roots, Path, Path]) -> None:
    roots, first, second = two
    assert roots.resolve("amr-7") == first / "amr-7"
    assert roots.resolve("amr-9/hot/x.mcap") == second / "amr-9" / "hot" / "x.mcap"
    assert roots.resolve(str(second / "amr-9")) == second / "amr-9"
    assert roots.resolve(".") == first
    assert roots.resolve(str(second)) == second


@pytest.mark.parametrize(
    "name",
    [
        "amr-7/../amr-7",
        "../second/amr-9",
        "out",
        "out/anything",
        "/etc/passwd",
        "nowhere",
        "a\x00b",
    ],
)
def test_anything_else_is_refused_naming_the_roots(
    two: tuple[Roots, Path, Path], name: str
) -> None:
    roots, first, _ = two
    with pytest.raises(UnsafePathError, match="under the configured roots") as refused:
        roots.resolve(name)
    assert str(first) in str(refused.value)


def test_a_fifo_is_refused_not_waited_on(two: tuple[Roots, Path, Path]) -> None:
    roots, first, _ = two
    os.mkfifo(first / "pipe.mcap")
    with pytest.raises(UnsafePathError, match="a FIFO"):
        roots.resolve("pipe.mcap")


def test_a_root_must_be_a_folder(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="not a folder"):
        Roots.of([tmp_path / "nowhere"])
    with pytest.raises(UsageError, match="at least one"):
        Roots.of([])


def test_the_fingerprint_changes_with_a_file_and_ignores_links(tmp_path: Path) -> None:
    log = tmp_path / "log"
    (log / "hot").mkdir(parents=True)
    segment = log / "hot" / "a.mcap"
    segment.write_bytes(b"x" * 10)
    before = fingerprint(log)
    (log / "hot" / "link.mcap").symlink_to(segment)
    assert fingerprint(log) == before
    with segment.open("ab") as f:
        f.write(b"y")
    assert fingerprint(log) != before
    assert fingerprint(segment) == (("a.mcap", 11, segment.stat().st_mtime_ns),)
