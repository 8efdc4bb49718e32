"""The compaction fault campaign: kill -9 anywhere, decayed copies, a full disk.

After every fault, one more ``compact`` completes the job: every cycle of the original log is
read exactly once through ``open_log``, nothing is left in two tiers or half-written, and
``verify`` finds the root clean. bench/bench_compaction_faults.py runs the longer campaign.
"""

from __future__ import annotations

import errno
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, BinaryIO, cast

import pytest

from tests.trace_runtime.tier_logs import cycle_key, make_root
from trace_audit.verify import verify_log
from trace_runtime import open_log, open_segment
from trace_runtime.tiers import ColdOptions, compact
from trace_runtime.tiers._files import open_partial

REPO = Path(__file__).resolve().parents[3]
SMALL_BLOCKS = ColdOptions(block_cycles=8)

_CHILD = """
import os, signal, sys
from pathlib import Path
sys.path.insert(0, {repo!r})
from trace_runtime.tiers import ColdOptions, compact
from trace_runtime.tiers import replace as module

target, nth = {hook!r}
calls = [0]

def kill_after(owner, name):
    real = getattr(owner, name)
    def wrapped(*args, **kwargs):
        result = real(*args, **kwargs)
        calls[0] += 1
        if calls[0] == nth:
            os.kill(os.getpid(), signal.SIGKILL)
        return result
    setattr(owner, name, wrapped)

if target == "replace":  # the replacement renamed in, its source not yet removed
    kill_after(module.os, "replace")
elif target == "fsync":
    kill_after(os, "fsync")
elif target == "write_batch":
    from trace_runtime.logger.segment_writer import SegmentWriter
    kill_after(SegmentWriter, "write_batch")
print("start", flush=True)
compact({root!r}, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=8),
        progress=lambda event: print("block", flush=True))
print("done", flush=True)
"""


def kill_compaction(root: Path, rng: random.Random) -> str:
    """Run ``compact`` in a child and SIGKILL it at a random point; say where."""
    if rng.random() < 0.5:
        hook: tuple[str, int] = (rng.choice(["replace", "fsync", "write_batch"]), rng.randint(1, 6))
    else:
        hook = ("none", 0)
    code = _CHILD.format(repo=str(REPO), root=str(root), hook=hook)
    with subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=REPO
    ) as proc:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "start"
        where = f"after {hook[0]} #{hook[1]}"
        if hook[0] == "none":
            blocks = rng.randrange(0, 12)
            for _ in range(blocks):
                proc.stdout.readline()
            delay = rng.uniform(0.0, 0.02)
            time.sleep(delay)
            proc.send_signal(signal.SIGKILL)
            where = f"{blocks} blocks + {delay * 1000:.0f} ms"
        proc.communicate(timeout=60)
    return where


def check_completed(root: Path, original: list[Any], names: list[str]) -> None:
    """One more run completes: every cycle once, one tier per segment, verify clean."""
    report = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    assert not report.failed and not report.held, (report.segments, report.leftovers)
    assert not list(root.rglob("*.partial"))
    assert sorted(p.relative_to(root).as_posix() for p in root.glob("*/*.mcap")) == [
        f"cold/{n}" for n in names
    ]
    assert [cycle_key(c) for c in open_log(root).iter_cycles()] == original
    verified = verify_log(root)
    assert verified.ok, verified.findings


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Any], list[str]]:
    root = make_root(tmp_path_factory.mktemp("faults") / "log", cycles=30, segments=3)
    original = [cycle_key(c) for c in open_log(root).iter_cycles()]
    names = sorted(p.name for p in (root / "hot").glob("*.mcap"))
    return root, original, names


@pytest.mark.parametrize("seed", range(10))
def test_kill_9_anywhere_then_compact_again_loses_nothing(
    template: tuple[Path, list[Any], list[str]], tmp_path: Path, seed: int
) -> None:
    source, original, names = template
    root = tmp_path / "root"
    shutil.copytree(source, root)
    where = kill_compaction(root, random.Random(seed))
    try:
        check_completed(root, original, names)
    except AssertionError as err:
        raise AssertionError(f"killed {where}: {err}") from err


# --- decayed duplicates ---------------------------------------------------------------------


def _decay(path: Path, rng: random.Random) -> None:
    chunks = open_segment(path).chunks()
    offset = rng.choice(chunks).offset
    data = bytearray(path.read_bytes())
    data[offset + 80] ^= 1 << rng.randrange(8)
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("decayed", ["source", "replacement"])
def test_a_decayed_copy_of_an_interrupted_compaction_costs_nothing(
    template: tuple[Path, list[Any], list[str]], tmp_path: Path, decayed: str, seed: int
) -> None:
    """Killed after the rename, then one copy decays: the other one completes the job."""
    source, original, names = template
    done = tmp_path / "done"
    shutil.copytree(source, done)
    compact(done, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    rng = random.Random(seed)
    name = rng.choice(names)
    root = tmp_path / "root"
    shutil.copytree(source, root)
    (root / "cold").mkdir()
    shutil.copy(done / "cold" / name, root / "cold" / name)
    _decay(root / ("hot" if decayed == "source" else "cold") / name, rng)
    check_completed(root, original, names)


def test_both_copies_decayed_are_both_kept(
    template: tuple[Path, list[Any], list[str]], tmp_path: Path
) -> None:
    source, _original, names = template
    done = tmp_path / "done"
    shutil.copytree(source, done)
    compact(done, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    root = tmp_path / "root"
    shutil.copytree(source, root)
    (root / "cold").mkdir()
    name = names[1]
    shutil.copy(done / "cold" / name, root / "cold" / name)
    rng = random.Random(5)
    for tier in ("hot", "cold"):
        _decay(root / tier / name, rng)
    before = {t: (root / t / name).read_bytes() for t in ("hot", "cold")}
    report = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    (held,) = report.held
    assert held.path == f"hot/{name}"
    assert {t: (root / t / name).read_bytes() for t in ("hot", "cold")} == before


# --- a full disk ----------------------------------------------------------------------------


class FullDisk:
    """A partial file on a disk with ``room`` bytes left: short write, then ENOSPC."""

    def __init__(self, file: BinaryIO, room: int) -> None:
        self._file = file
        self._room = room

    def write(self, data: bytes) -> int:
        if len(data) > self._room:
            self._file.write(data[: self._room])
            self._room = 0
            raise OSError(errno.ENOSPC, "No space left on device")
        self._room -= len(data)
        return self._file.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._file, name)


@pytest.fixture(scope="module")
def cold_size(template: tuple[Path, list[Any], list[str]], tmp_path_factory: Any) -> int:
    """Bytes of the smallest cold segment this root compacts to."""
    root = tmp_path_factory.mktemp("size") / "root"
    shutil.copytree(template[0], root)
    compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    return min(p.stat().st_size for p in root.glob("cold/*.mcap"))


# 0: the very first write (header, session, marker) fails; then inside the first write,
# mid-data, in the last block, in the summary at the end
@pytest.mark.parametrize("share", [0.0, 0.1, 0.5, 0.9, 0.995])
def test_a_full_disk_fails_the_segment_cleanly_and_a_later_run_completes(
    template: tuple[Path, list[Any], list[str]], tmp_path: Path, cold_size: int, share: float
) -> None:
    source, original, names = template
    root = tmp_path / "root"
    shutil.copytree(source, root)
    room = int(cold_size * share)
    before = {p.name: p.read_bytes() for p in (root / "hot").glob("*.mcap")}

    def opener(path: Path) -> BinaryIO:
        return cast(BinaryIO, FullDisk(open_partial(path), room))

    report = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS, opener=opener)
    assert report.failed and all(s.status == "failed" for s in report.segments)
    assert all("No space left" in s.detail for s in report.failed), report.failed
    assert not list(root.rglob("*.partial"))  # its own half-written files removed
    assert {p.name: p.read_bytes() for p in (root / "hot").glob("*.mcap")} == before
    assert not list(root.glob("cold/*.mcap"))
    check_completed(root, original, names)
