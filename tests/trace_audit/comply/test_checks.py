"""Each check of ``comply`` fails on a root crafted to break it, and only that check's
verdict is asked: a one-clause profile per check, run through the CLI. Segments are
tampered with the plain ``mcap`` Writer (``rewrite_segment``), as an attacker would."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson

from tests.trace_audit.comply.conftest import Comply, comply, trusted
from tests.trace_audit.conftest import fill_cycle, rewrite_segment, write_log
from tests.trace_audit.witness.conftest import Keys, run_cli
from trace_runtime import AuditLogger, LoggerConfig


def _one_check(folder: Path, check: str, keep: str = "") -> str:
    path = folder / f"only-{check}.toml"
    path.write_text(
        f'name = "only-{check}"\n[[clause]]\nreference = "Test {check}"\n'
        f'summary = "the {check} check alone"\nchecks = ["{check}"]\n{keep}'
    )
    return str(path)


def _verdict(done: Comply, check: str) -> dict[str, Any]:
    found = done.clause(f"Test {check}")["checks"][0]
    assert found["check"] == check
    return found


def _tampered(tmp_path: Path, mutate: Callable[[Any], bytes | None]) -> Path:
    root = write_log(tmp_path / "root")
    segment = next((root / "hot").glob("*.mcap"))
    rewrite_segment(segment, tmp_path / "rewritten.mcap", mutate)
    shutil.move(tmp_path / "rewritten.mcap", segment)
    return root


def test_versions_fails_on_a_robot_that_names_no_version(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root")
    done = comply(root, _one_check(tmp_path, "versions"))
    assert done.code == 1 and _verdict(done, "versions")["verdict"] == "not met"


def test_signed_fails_on_unsigned_checkpoints_and_without_a_key(
    unsigned_root: Path, witnessed_root: Path, comply_keys: Keys, tmp_path: Path
) -> None:
    profile = _one_check(tmp_path, "signed")
    unsigned = comply(unsigned_root, profile, "--key", str(comply_keys.robot_pub))
    assert unsigned.code == 1
    assert any("unsigned_checkpoint" in e for e in _verdict(unsigned, "signed")["evidence"])
    no_key = comply(witnessed_root, profile)
    assert no_key.code == 1 and "--key" in _verdict(no_key, "signed")["fix"]
    assert comply(witnessed_root, profile, "--key", str(comply_keys.robot_pub)).code == 0


def test_witnessed_fails_when_no_witness_cosigned(
    witnessed_root: Path, comply_keys: Keys, copy_of: Callable[[Path], Path], tmp_path: Path
) -> None:
    profile = _one_check(tmp_path, "witnessed")
    assert comply(witnessed_root, profile, *trusted(comply_keys)).code == 0
    root = copy_of(witnessed_root)
    shutil.rmtree(root / "witness")
    done = comply(root, profile, *trusted(comply_keys))
    assert done.code == 1
    assert any("no cosigned checkpoint" in e for e in _verdict(done, "witnessed")["evidence"])
    unchecked = comply(witnessed_root, profile, "--key", str(comply_keys.robot_pub))
    assert unchecked.code == 1  # a cosignature nobody checked vouches for nothing


def test_gaps_fails_on_cycles_cut_out_without_a_declaration(tmp_path: Path) -> None:
    def cut(msg: Any) -> bytes | None:
        data: bytes = msg.data
        if msg.topic.startswith("/trace/") and msg.topic != "/trace/checkpoint":
            cycle = orjson.loads(data).get("cycle")
            if cycle in (20, 21, 22):
                return None
        return data

    done = comply(_tampered(tmp_path, cut), _one_check(tmp_path, "gaps"))
    assert done.code == 1
    evidence = _verdict(done, "gaps")["evidence"]
    assert any("20" in e for e in evidence[:-1]), evidence


def test_chain_fails_on_a_record_changed_after_it_was_sealed(tmp_path: Path) -> None:
    def edit(msg: Any) -> bytes | None:
        data: bytes = msg.data
        if msg.topic == "/trace/action" and orjson.loads(data).get("cycle") == 30:
            return data.replace(b'"command":"', b'"command":"X', 1)
        return data

    root = _tampered(tmp_path, edit)
    done = comply(root, _one_check(tmp_path, "chain"))
    assert done.code == 1
    assert any("modified" in e for e in _verdict(done, "chain")["evidence"])
    assert comply(root, _one_check(tmp_path, "gaps")).code == 0  # a change is not a gap


def test_retention_fails_until_the_profile_is_adopted(tmp_path: Path) -> None:
    root = write_log(tmp_path / "root")
    profile = _one_check(tmp_path, "retention", "keep_days = 184\nfull_detail = true\n")
    before = comply(root, profile)
    assert before.code == 1
    assert "no compliance profile adopted" in _verdict(before, "retention")["evidence"][0]
    assert comply(root, profile, "--adopt").code == 0
    # what compaction was forced to summarise within the period is named
    forced = run_cli("compact", str(root), "--tier", "warm", "--older-than", "0",
                     "--include-unfinished", "--override-compliance", "--json")  # fmt: skip
    assert forced.returncode == 0, forced.stderr
    after = comply(root, profile)
    assert after.code == 1
    assert any("summarised (warm)" in e for e in _verdict(after, "retention")["evidence"])


def test_retention_fails_on_a_deletion_the_journal_records_within_the_period(
    tmp_path: Path,
) -> None:
    root = write_log(tmp_path / "root")
    profile = _one_check(tmp_path, "retention", "keep_days = 184\n")
    assert comply(root, profile, "--adopt").code == 0
    line = {"path": "cold/amr-7_000000.mcap", "robot": "amr-7", "segment": 0,
            "end_ns": 99_000_000_000, "deleted_at_ns": 1}  # fmt: skip
    (root / "retention.jsonl").write_bytes(orjson.dumps(line) + b"\n")
    done = comply(root, profile)
    assert done.code == 1
    assert any("deleted by retention" in e for e in _verdict(done, "retention")["evidence"])


class _NoChecks:
    """A cycle builder whose execution records name no safety-rule check."""

    def __init__(self, builder: Any) -> None:
        self._builder = builder

    def __getattr__(self, name: str) -> Any:
        return getattr(self._builder, name)

    def execution(self, record: dict[str, Any]) -> None:
        self._builder.execution({**record, "checks": []})


def test_safety_rules_fails_when_decisions_record_no_check(tmp_path: Path) -> None:
    logger = AuditLogger(tmp_path / "root", robot_id="amr-7", period_s=0.1,
                         software_version="nav 1", policy_version="p1",
                         config=LoggerConfig(threaded=False, fsync_interval_s=None))  # fmt: skip
    for i in range(20):
        c = logger.cycle(100_000_000_000 + i * 100_000_000)
        fill_cycle(_NoChecks(c), "clear")  # type: ignore[arg-type]
        c.commit()
    logger.close()
    done = comply(tmp_path / "root", _one_check(tmp_path, "safety_rules"))
    assert done.code == 1
    assert (
        "20 of 20 decisions record no safety-rule check"
        in (_verdict(done, "safety_rules")["evidence"][0])
    )


def test_every_check_has_a_test_here() -> None:
    from trace_audit.comply.profile import CHECK_NAMES

    names = {n.removeprefix("test_").split("_")[0] for n in globals() if n.startswith("test_")}
    assert {c.split("_")[0] for c in CHECK_NAMES} <= names


def _versioned_root(root: Path, versions: list[str]) -> Path:
    """A robot restarted once per version: a segment each, its chain continued."""
    t_ns = 100_000_000_000
    for version in versions:
        logger = AuditLogger(
            root,
            robot_id="amr-7",
            period_s=0.1,
            software_version=f"nav {version}",
            policy_version="p1",
            config=LoggerConfig(threaded=False, fsync_interval_s=None),
        )
        for _ in range(10):
            c = logger.cycle(t_ns)
            fill_cycle(c, "clear")
            c.commit()
            t_ns += 100_000_000
        logger.close()
    return root


def test_versions_lists_each_change_with_its_time_and_fails_on_one_not_visible(
    tmp_path: Path,
) -> None:
    root = _versioned_root(tmp_path / "root", ["1.0", "1.1", "2.0"])
    profile = _one_check(tmp_path, "versions")
    done = comply(root, profile)
    assert done.code == 0, done.stderr
    evidence = _verdict(done, "versions")["evidence"]
    assert evidence[1:] == [
        "amr-7: at 101.000 s (segment 1) software 'nav 1.0' -> 'nav 1.1', policy 'p1' -> 'p1'",
        "amr-7: at 102.000 s (segment 2) software 'nav 1.1' -> 'nav 2.0', policy 'p1' -> 'p1'",
    ]
    (root / "hot" / "amr-7_000001.mcap").unlink()  # the segment that ran 1.1
    cut = comply(root, profile)
    assert cut.code == 1
    assert (
        "not visible, segments 1..1 between are not here"
        in (_verdict(cut, "versions")["evidence"][0])
    )
