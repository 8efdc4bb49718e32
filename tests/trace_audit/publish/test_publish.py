"""``trace-audit publish`` from the outside: the tiles are the robot's own tree (its seals'
leaf hashes, the spec's tile shapes), a second run writes only what is new and rewrites
nothing, and what cannot be published is refused in one line (an unsigned log, exit 2) or
named as a problem with nothing replaced (exit 1)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from tests.outside import cli, one_line, snapshot
from tests.trace_audit.conftest import fill_cycle
from tests.trace_audit.publish.conftest import RobotKey
from tests.trace_audit.witness.test_tail import PERIOD_NS, T0_NS, write
from trace_audit.publish.tiler import TileBuilder
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.reading.chain_tree import robot_leaves
from trace_runtime.reading.logset import open_log
from trace_runtime.tlog.merkle import leaf_hash, root_of
from trace_runtime.tlog.signed_note import parse_checkpoint
from trace_runtime.tlog.tiles import bundle_entries, encode_bundle, tile_index_path, tile_path


def test_tile_paths_as_the_spec_spells_them() -> None:
    assert tile_index_path(1234067) == "x001/x234/067"
    assert tile_index_path(0) == "000"
    assert tile_index_path(1000) == "x001/000"
    assert tile_path(2, 5, 17) == "tile/2/005.p/17"


def test_a_tree_of_70000_has_the_tiles_the_spec_lists() -> None:
    """The spec's example: 273 full level-0 tiles, a partial one of 112, one full level-1
    tile, a partial one of 17, a partial level-2 tile of 1; each hash the root of its leaves."""
    builder = TileBuilder()
    leaves = [i.to_bytes(4, "big") for i in range(70_000)]
    full = [f.path for entry in leaves for f in builder.append(entry) if "entries" not in f.path]
    assert len([p for p in full if p.startswith("tile/0/")]) == 273
    assert [p for p in full if not p.startswith("tile/0/")] == ["tile/1/000"]
    partial = {f.path: f.data for f in builder.partial_tiles()}
    assert sorted(partial) == ["tile/0/273.p/112", "tile/1/001.p/17", "tile/2/000.p/1"]
    hashes = [leaf_hash(e) for e in leaves]
    assert partial["tile/0/273.p/112"] == b"".join(hashes[273 * 256 :])
    level1 = partial["tile/1/001.p/17"]
    assert level1[32:64] == root_of(hashes[257 * 256 : 258 * 256])
    assert partial["tile/2/000.p/1"] == root_of(hashes[: 256 * 256])
    assert builder.root() == root_of(hashes)
    bundle = builder.partial_bundle()
    assert bundle is not None and bundle.path == "tile/entries/273.p/112"
    assert bundle_entries(bundle.data) == leaves[273 * 256 :]


@given(st.lists(st.binary(max_size=300), max_size=40))
def test_entry_bundles_round_trip(entries: list[bytes]) -> None:
    assert bundle_entries(encode_bundle(entries)) == entries


def publish(root: Path, out: Path) -> dict[str, Any]:
    done = cli("publish", root, "--out", out, "--json")
    assert done.returncode in (0, 1), done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    report["exit"] = done.returncode
    return report


def test_the_tiles_are_the_robots_tree_and_a_second_run_rewrites_nothing(
    tmp_path: Path, robot_key: RobotKey
) -> None:
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, robot_key.private, range(300))
    first = publish(root, out)["robots"][0]
    folder = out / "amr-7"
    note = (folder / "checkpoint").read_text()
    body = parse_checkpoint(note[: note.rindex("\n\n") + 1])
    assert body.size == first["tree_size"] == 300
    leaves = robot_leaves(open_log(root), "amr-7")
    assert (folder / "tile/0/000").read_bytes() == b"".join(leaves[:256])
    assert (folder / "tile/0/001.p/44").read_bytes() == b"".join(leaves[256:300])
    assert [leaf_hash(e) for e in bundle_entries((folder / "tile/entries/000").read_bytes())] \
        == leaves[:256]  # fmt: skip
    assert body.root == root_of(leaves)
    assert first["checkpoints"] == 30  # a signed checkpoint a second: 30 partial tiles
    assert len(list((folder / "tile/0/001.p").iterdir())) == 30 - 25  # the others were in 000
    before = snapshot(out)
    inodes = {p: p.stat().st_ino for p in folder.rglob("*")}
    again = publish(root, out)["robots"][0]
    assert again["written"] == 0 and again["kept"] == first["written"]
    assert snapshot(out) == before
    assert {p: p.stat().st_ino for p in folder.rglob("*")} == inodes
    assert sorted(p.name for p in out.iterdir()) == ["amr-7"]  # the lock is not left behind


def test_an_unsigned_log_is_refused(tmp_path: Path) -> None:
    root, out = tmp_path / "root", tmp_path / "out"
    config = LoggerConfig(threaded=False, fsync_interval_s=None, checkpoint_interval_s=1.0)
    logger = AuditLogger(root, robot_id="amr-7", period_s=0.1, config=config)
    for i in range(30):
        cycle = logger.cycle(T0_NS + i * PERIOD_NS)
        fill_cycle(cycle, "clear")
        cycle.commit()
    logger.close()
    done = cli("publish", root, "--out", out)
    one_line(done, 2, "amr-7", "no signed checkpoint")
    assert not out.exists()


def test_a_published_tile_that_differs_is_named_and_not_replaced(
    tmp_path: Path, robot_key: RobotKey
) -> None:
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, robot_key.private, range(300))
    publish(root, out)
    tile = out / "amr-7" / "tile/0/000"
    altered = bytes([tile.read_bytes()[0] ^ 1]) + tile.read_bytes()[1:]
    tile.write_bytes(altered)
    checkpoint = (out / "amr-7" / "checkpoint").read_bytes()
    write(root, robot_key.private, range(300, 400))
    report = publish(root, out)
    assert report["exit"] == 1
    [problem] = report["robots"][0]["problems"]
    assert "tile/0/000" in problem and "nothing replaced" in problem
    assert tile.read_bytes() == altered
    assert (out / "amr-7" / "checkpoint").read_bytes() == checkpoint
    assert not list(out.rglob("*.partial"))  # this run's staged files are gone


def test_an_older_copy_of_the_log_does_not_roll_the_published_tree_back(
    tmp_path: Path, robot_key: RobotKey
) -> None:
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, robot_key.private, range(200))
    older = tmp_path / "older"
    shutil.copytree(root, older)
    write(root, robot_key.private, range(200, 400))
    publish(root, out)
    checkpoint = (out / "amr-7" / "checkpoint").read_bytes()
    report = publish(older, out)
    assert report["exit"] == 1
    [problem] = report["robots"][0]["problems"]
    assert "tree of 400 seals, beyond the 200" in problem
    assert (out / "amr-7" / "checkpoint").read_bytes() == checkpoint


def test_a_file_where_a_tile_folder_belongs_is_refused(tmp_path: Path, robot_key: RobotKey) -> None:
    root, out = tmp_path / "root", tmp_path / "out"
    write(root, robot_key.private, range(20))
    (out / "amr-7").mkdir(parents=True)
    (out / "amr-7" / "tile").write_text("not a folder")
    one_line(cli("publish", root, "--out", out), 3, "tile")


def test_another_history_of_the_same_robot_is_a_fork_not_a_replacement(
    tmp_path: Path, robot_key: RobotKey
) -> None:
    """The same robot and key, another history (re-signed from genesis): what the folder
    serves is not replaced, whatever the other log's own checkpoints say."""
    first, other, out = tmp_path / "first", tmp_path / "other", tmp_path / "out"
    write(first, robot_key.private, range(200))
    write(other, robot_key.private, range(1000, 1300))
    publish(first, out)
    before = snapshot(out)
    report = publish(other, out)
    assert report["exit"] == 1
    [problem] = report["robots"][0]["problems"]
    assert "differs from this log's" in problem or "another root" in problem
    assert snapshot(out) == before
