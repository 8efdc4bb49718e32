"""For random roots seeded with links, FIFOs and files where the tools read and write, no
command modifies anything outside the root, none hangs and none traces back."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.outside import cli, snapshot
from tests.trace_audit.conftest import T0_NS, write_log

# Where the tools read, write, rename or delete inside a root.
PLACES = (
    "catalog.json",
    "catalog.json.partial",
    "retention.jsonl",
    ".compact.lock",
    "cold",
    "warm",
    "cold/r1_000000.mcap",
    "cold/r1_000000.mcap.partial",
    "hot/r1_000004.mcap",
)
KINDS = ("link-file", "link-dir", "fifo", "file")
COMMANDS = (
    ("catalog", "{root}", "--refresh"),
    ("explain", "{root}", "--t", f"{T0_NS / 1e9 + 5.0:.1f}"),
    ("compact", "{root}", "--tier", "cold", "--older-than", "0", "--retention", "0s"),
    ("verify", "{root}"),
)


def _plant(root: Path, outside: Path, place: str, kind: str) -> None:
    path = root / place
    if path.exists() or path.is_symlink() or path.parent.is_symlink():
        return  # planted already, or its folder is itself a plant (leading outside)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError:  # a file planted where the folder would be
        return
    if kind == "link-file":
        path.symlink_to(outside / "victim.txt")
    elif kind == "link-dir":
        path.symlink_to(outside / "folder", target_is_directory=True)
    elif kind == "fifo":
        os.mkfifo(path)
    else:
        path.write_bytes(b"someone else's bytes\n")


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(
    plants=st.lists(st.tuples(st.sampled_from(PLACES), st.sampled_from(KINDS)), max_size=4),
    command=st.sampled_from(COMMANDS),
)
def test_no_command_touches_anything_outside_the_root(
    plants: list[tuple[str, str]], command: tuple[str, ...]
) -> None:
    base = Path(tempfile.mkdtemp(prefix="untrusted-root-"))
    try:
        outside = base / "outside"
        (outside / "folder").mkdir(parents=True)
        (outside / "victim.txt").write_bytes(b"the victim's own words\n")
        (outside / "folder" / "r1_000000.mcap").write_bytes(b"not a segment\n")
        root = write_log(base / "root", robot_id="r1", max_segment_s=3.0)
        for place, kind in plants:
            _plant(root, outside, place, kind)
        before = snapshot(outside)
        listed = sorted(p.name for p in (outside / "folder").iterdir())
        done = cli(*(part.format(root=root) for part in command), timeout_s=60)
        assert "Traceback" not in done.stderr, done.stderr
        assert done.returncode in (0, 1, 2, 3, 4), done.stderr
        assert snapshot(outside) == before
        assert sorted(p.name for p in (outside / "folder").iterdir()) == listed
    finally:
        shutil.rmtree(base, ignore_errors=True)
