"""Compaction is atomic and resumable, idempotent, ages segments as documented, and retention
deletes only compacted segments that verify."""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from tests.trace_runtime.tier_logs import T0_NS, cycle_key, make_root
from trace_runtime import AuditLogger, LoggerConfig, open_log, open_segment
from trace_runtime.encoding.cycles import RawMessage
from trace_runtime.testing import synthetic_cycle
from trace_runtime.tier_formats.cold import BlockEncoder
from trace_runtime.tiers import (
    CATALOG_NAME,
    ColdOptions,
    _files,
    compact,
    load_catalog,
    parse_duration,
    refresh_catalog,
)
from trace_runtime.tiers import write as write_module

REPO = Path(__file__).resolve().parents[3]
SMALL_BLOCKS = ColdOptions(block_cycles=16)


def _state(root: Path) -> dict[str, bytes]:
    """Every file under the root (but the lock) and its bytes."""
    return {
        p.relative_to(root).as_posix(): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".compact.lock"
    }


def _segment_names(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.glob("*/*.mcap"))


def test_compacting_twice_changes_nothing(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=60, segments=3)
    first = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    assert [s.status for s in first.segments] == ["compacted"] * 3
    assert first.bytes_after < first.bytes_before
    before = _state(root)
    second = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    assert second.segments == [] and second.leftovers == []
    assert _state(root) == before
    # warm after cold has nothing to take either (warm takes only from hot)
    assert compact(root, "warm", older_than_ns=0).segments == []
    assert _state(root) == before


def test_parallel_workers_give_a_segment_with_the_same_cycles(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=100, segments=1)
    hot = list(open_log(root).iter_cycles())
    report = compact(root, "cold", older_than_ns=0, cold=ColdOptions(block_cycles=16, jobs=2))
    assert [s.status for s in report.segments] == ["compacted"]
    assert list(open_log(root).iter_cycles()) == hot


def test_workers_compact_segments_into_the_same_files_as_one_process(tmp_path: Path) -> None:
    """Segments spread over worker processes (each reading its own file) come out byte for
    byte as one process writes them, swapped in in order, with the catalog and progress."""
    template = make_root(tmp_path / "template", cycles=90, segments=3)
    serial, parallel = tmp_path / "serial", tmp_path / "parallel"
    shutil.copytree(template, serial)
    shutil.copytree(template, parallel)
    one = compact(serial, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    seen: list[int] = []
    two = compact(
        parallel,
        "cold",
        older_than_ns=0,
        cold=ColdOptions(block_cycles=16, jobs=2),
        progress=lambda event: seen.append(event.cycles_done),
    )
    assert [s.status for s in two.segments] == ["compacted"] * 3
    assert [(s.source, s.target, s.cycles) for s in two.segments] == [
        (s.source, s.target, s.cycles) for s in one.segments
    ]
    assert seen == sorted(seen) and seen[-1] == two.cycles
    names = sorted(p.name for p in (serial / "cold").glob("*.mcap"))
    assert names == sorted(p.name for p in (parallel / "cold").glob("*.mcap"))
    for name in names:
        assert (serial / "cold" / name).read_bytes() == (parallel / "cold" / name).read_bytes()
    assert not list((parallel / "hot").glob("*.mcap"))
    assert not list(parallel.rglob("*.partial"))
    catalog = load_catalog(parallel)
    assert catalog is not None
    assert sorted(e.path for e in catalog.entries) == [f"cold/{n}" for n in names]


def test_dry_run_changes_nothing(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=40, segments=2)
    (root / "cold").mkdir()
    (root / "cold" / "x.mcap.partial").write_bytes(b"left by a killed run")
    before = _state(root)
    report = compact(root, "cold", older_than_ns=0, dry_run=True)
    assert [s.status for s in report.segments] == ["planned", "planned"]
    assert [leftover.path for leftover in report.leftovers] == ["cold/x.mcap.partial"]
    assert _state(root) == before


def test_age_is_measured_against_the_newest_log_time(tmp_path: Path) -> None:
    # segments 0 and 1 end 2 and 1 hours before the newest log time; segment 2 is the newest
    root = tmp_path / "log"
    for hours in (0, 1, 2):
        make_root(root, cycles=20, t0_ns=T0_NS + hours * 3600 * 10**9, drop_at=None)
    report = compact(root, "warm", older_than_ns=parse_duration("90m"))
    assert [s.segment for s in report.segments] == [0]
    assert report.reference == "newest log time"
    assert report.reference_ns == open_log(root).end_ns
    assert {s.detail for s in report.skipped} == {"newer than the cutoff"}
    # a given reference time, or the wall clock (these logs are from 1970: all old)
    later = compact(root, "warm", older_than_ns=parse_duration("30m"), now_ns=report.reference_ns)
    assert [s.segment for s in later.segments] == [1]
    final = compact(root, "warm", wall_clock=True)
    assert final.reference == "wall clock" and [s.segment for s in final.segments] == [2]


def test_the_newest_unfinished_hot_segment_is_left_to_its_logger(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=20)
    config = LoggerConfig(threaded=False, fsync_interval_s=None)
    logger = AuditLogger(root, robot_id="amr-1", period_s=0.1, config=config)
    for i in range(10):
        p, b, a, e = synthetic_cycle(i)
        logger.log_cycle(T0_NS + (100 + i) * 10**8, perception=p, belief=b, action=a, execution=e)
    try:
        report = compact(root, "cold", older_than_ns=0)
        assert [s.segment for s in report.segments] == [0]
        assert [s.detail for s in report.skipped] == [
            "unfinished newest hot segment: its logger may still be writing it"
        ]
        live = next((root / "hot").glob("*.mcap"))
        cycles = list(open_segment(live).iter_cycles())
        report = compact(root, "cold", older_than_ns=0, include_unfinished=True)
        assert [s.segment for s in report.segments] == [1]
        assert list(open_segment(root / "cold" / live.name).iter_cycles()) == cycles
    finally:
        logger.close()


def _lose_one_message(messages: list[RawMessage]) -> list[RawMessage]:
    first, *rest = messages
    return [RawMessage(first.topic, first.sequence, first.log_time_ns, b'{"lost":true}'), *rest]


@pytest.mark.parametrize("where", ["codec", "pipeline"])
def test_a_replacement_that_does_not_verify_leaves_the_source(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """A codec that loses data, or a pipeline that hands it the wrong messages, is caught."""
    root = make_root(tmp_path / "log", cycles=40)
    before = _state(root)
    if where == "codec":
        real_encode = BlockEncoder._encode

        def lossy(self: BlockEncoder, messages: Any, *args: Any, **kwargs: Any) -> bytes:
            return real_encode(self, _lose_one_message(messages), *args, **kwargs)

        monkeypatch.setattr(BlockEncoder, "_encode", lossy)
    else:
        real_split = write_module.split_plain

        def dropping(block: Any) -> Any:
            kept, plain, positions = real_split(block)
            return _lose_one_message(kept), plain, positions

        monkeypatch.setattr(write_module, "split_plain", dropping)
    report = compact(root, "cold", older_than_ns=0)
    assert [s.status for s in report.segments] == ["failed"]
    detail = report.segments[0].detail
    assert "codec bug" in detail or "does not decode to the source messages" in detail
    after = _state(root)
    assert {k: v for k, v in after.items() if k != CATALOG_NAME} == before
    assert not list(root.rglob("*.partial"))


def test_leftovers_of_a_killed_run_are_completed_or_discarded(tmp_path: Path) -> None:
    template = make_root(tmp_path / "template", cycles=40, segments=2)
    done = tmp_path / "done"
    shutil.copytree(template, done)
    compact(done, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    name0, name1 = (p.name for p in sorted((template / "hot").glob("*.mcap")))

    # killed after the rename of segment 0, before its source was removed; and mid-write of 1
    root = tmp_path / "root"
    shutil.copytree(template, root)
    (root / "cold").mkdir()
    shutil.copy(done / "cold" / name0, root / "cold" / name0)
    (root / "cold" / (name1 + ".partial")).write_bytes((done / "cold" / name1).read_bytes()[:999])
    original = [cycle_key(c) for c in open_log(template).iter_cycles()]
    report = compact(root, "cold", older_than_ns=parse_duration("1000d"))  # recovery only
    actions = {leftover.path: leftover.action for leftover in report.leftovers}
    assert "unfinished write discarded" in actions[f"cold/{name1}.partial"]
    assert "verified; source removed" in actions[f"hot/{name0}"]
    assert _segment_names(root) == [f"cold/{name0}", f"hot/{name1}"]
    assert [cycle_key(c) for c in open_log(root).iter_cycles()] == original

    # a decayed replacement is discarded (its source verifies), then redone
    shutil.copy(done / "cold" / name1, root / "cold" / name1)
    decayed = bytearray((root / "cold" / name1).read_bytes())
    decayed[open_segment(root / "cold" / name1).chunks()[0].offset + 80] ^= 0x10
    (root / "cold" / name1).write_bytes(bytes(decayed))
    report = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    assert "did not verify" in report.leftovers[0].action
    assert [s.status for s in report.segments] == ["compacted"]
    assert _segment_names(root) == [f"cold/{name0}", f"cold/{name1}"]
    assert [cycle_key(c) for c in open_log(root).iter_cycles()] == original


def test_a_replacement_of_another_segment_that_verifies_is_held_not_deleted(
    tmp_path: Path,
) -> None:
    """Compaction never writes one segment's copy under another's name; when it finds one,
    both files verify on their own and neither is provably redundant: both are kept."""
    template = make_root(tmp_path / "template", cycles=40, segments=2)
    done = tmp_path / "done"
    shutil.copytree(template, done)
    compact(done, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    name0, name1 = (p.name for p in sorted((template / "hot").glob("*.mcap")))
    root = tmp_path / "root"
    shutil.copytree(template, root)
    (root / "cold").mkdir()
    shutil.copy(done / "cold" / name0, root / "cold" / name1)
    report = compact(root, "cold", older_than_ns=0, cold=SMALL_BLOCKS)
    (held,) = report.held
    assert held.path == f"hot/{name1}" and "both verify but differ" in held.action
    assert f"hot/{name1}" not in [s.source for s in report.segments]
    assert (root / "hot" / name1).exists() and (root / "cold" / name1).exists()


# --- kill -9 ------------------------------------------------------------------------------

_CHILD = """
import os, signal, sys
from pathlib import Path
sys.path.insert(0, {repo!r})
from trace_runtime.tiers import ColdOptions, compact
from trace_runtime.tiers import replace as module

target, when, nth = {kill!r}
calls = [0]

def wrap(owner, name):
    real = getattr(owner, name)
    def wrapped(*args, **kwargs):
        calls[0] += 1
        if calls[0] == nth and when == "before":
            os.kill(os.getpid(), signal.SIGKILL)
        result = real(*args, **kwargs)
        if calls[0] == nth and when == "after":
            os.kill(os.getpid(), signal.SIGKILL)
        return result
    setattr(owner, name, wrapped)

if target == "replace":
    wrap(module.os, "replace")
elif target == "unlink":
    wrap(Path, "unlink")
elif target == "fsync":
    wrap(os, "fsync")
elif target == "write_batch":
    from trace_runtime.logger.segment_writer import SegmentWriter
    wrap(SegmentWriter, "write_batch")
print("start", flush=True)
compact(
    {root!r}, {tier!r}, older_than_ns=0, cold=ColdOptions(block_cycles=16, jobs={jobs}),
    progress=lambda event: print("progress", event.cycles_done, flush=True),
)
print("done", flush=True)
"""


def _child(
    root: Path, tier: str, kill: tuple[str, str, int], jobs: int = 1
) -> subprocess.Popen[str]:
    code = _CHILD.format(repo=str(REPO), root=str(root), tier=tier, kill=kill, jobs=jobs)
    return subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, cwd=str(REPO)
    )


def _check_resumed(root: Path, tier: str, original: list[Any], names: list[str]) -> None:
    report = compact(root, tier, older_than_ns=0, cold=SMALL_BLOCKS)
    assert not report.failed
    assert not list(root.rglob("*.partial"))
    assert _segment_names(root) == [f"{tier}/{n}" for n in names]  # each segment exactly once
    cycles = list(open_log(root).iter_cycles())
    if tier == "cold":
        assert [cycle_key(c) for c in cycles] == original
    else:
        assert [(c.cycle, c.t_ns) for c in cycles] == [(k[0], k[1]) for k in original]
    catalog = load_catalog(root)
    assert catalog is not None
    assert [e.path for e in catalog.entries] == [e.path for e in refresh_catalog(root).entries]


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Any], list[str]]:
    root = make_root(tmp_path_factory.mktemp("kill") / "log", cycles=90, segments=3)
    original = [cycle_key(c) for c in open_log(root).iter_cycles()]
    names = sorted(p.name for p in (root / "hot").glob("*.mcap"))
    return root, original, names


@pytest.mark.parametrize(
    ("tier", "kill"),
    [
        ("cold", ("write_batch", "after", 2)),  # mid-write of the first segment
        ("cold", ("fsync", "after", 1)),  # first replacement written and synced, not verified
        ("cold", ("replace", "before", 1)),  # verified, not renamed in
        ("cold", ("replace", "after", 1)),  # renamed in, source still there
        ("cold", ("unlink", "before", 1)),  # catalog updated, source still there
        ("cold", ("unlink", "after", 2)),  # second source removed, directory not yet synced
        ("cold", ("replace", "after", 5)),  # later: around the third segment
        ("warm", ("write_batch", "after", 1)),
        ("warm", ("replace", "after", 1)),
        ("warm", ("unlink", "before", 2)),
    ],
)
def test_kill_9_at_each_step_loses_and_duplicates_nothing(
    tmp_path: Path, template: tuple[Path, list[Any], list[str]], kill: Any, tier: str
) -> None:
    source, original, names = template
    root = tmp_path / "root"
    shutil.copytree(source, root)
    proc = _child(root, tier, kill)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, out
    _check_resumed(root, tier, original, names)


def test_kill_9_at_random_moments(
    tmp_path: Path, template: tuple[Path, list[Any], list[str]]
) -> None:
    source, original, names = template
    rng = random.Random(int(os.environ.get("TRACE_KILL_SEED", "11")))
    for attempt in range(4):
        root = tmp_path / f"root{attempt}"
        shutil.copytree(source, root)
        proc = _child(root, "cold", ("none", "never", 0))
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "start"
        # somewhere after a random block of the 17 this run writes, up to 20 ms later
        for _ in range(rng.randrange(0, 17)):
            proc.stdout.readline()
        time.sleep(rng.uniform(0.0, 0.02))
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=60)
        _check_resumed(root, "cold", original, names)


def _children_of(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_kill_9_with_worker_processes_leaves_no_orphans(
    tmp_path: Path, template: tuple[Path, list[Any], list[str]]
) -> None:
    source, original, names = template
    root = tmp_path / "root"
    shutil.copytree(source, root)
    proc = _child(root, "cold", ("none", "never", 0), jobs=2)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "start"
    proc.stdout.readline()  # the workers have encoded a block
    workers = _children_of(proc.pid)
    assert len(workers) >= 2  # the two workers (and the resource tracker)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(Path(f"/proc/{w}").exists() for w in workers):
        time.sleep(0.1)
    alive = []
    for w in workers:
        try:
            state = Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":  # a zombie has exited; only its parent's wait is missing
            alive.append(w)
    assert not alive
    _check_resumed(root, "cold", original, names)


def test_compaction_rejects_bad_arguments(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=5)
    from trace_runtime.errors import LogReadError, UsageError

    with pytest.raises(UsageError):
        compact(root, "lukewarm")
    with pytest.raises(UsageError):
        compact(root, "warm", sources=["cold"])
    with pytest.raises(UsageError):
        compact(root, "cold", older_than_ns=-1)
    with pytest.raises(LogReadError):
        compact(tmp_path / "missing", "cold")


def test_one_compaction_per_root(tmp_path: Path) -> None:
    root = make_root(tmp_path / "log", cycles=5)
    from trace_runtime.errors import UsageError

    with _files.root_lock(root), pytest.raises(UsageError, match="another compaction"):
        compact(root, "cold", older_than_ns=0)
