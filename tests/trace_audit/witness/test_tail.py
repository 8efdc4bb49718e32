"""What a witness adds to ``verify``: a log root pushed to a real ``witness serve`` process,
then shortened as someone with the robot's disk would (the newest segment deleted, the
newest two, the newest cut in half, the root rolled back to an older copy). Each is CLEAN
without ``--witness``, as before, and a ``truncated_tail`` finding with it; a rewritten and
re-signed history is a ``fork``."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.trace_audit.conftest import fill_cycle
from tests.trace_audit.witness.conftest import Keys, WitnessProcess, run_cli
from trace_runtime import AuditLogger, LoggerConfig
from trace_runtime.tlog.keys import load_signer

T0_NS = 1_790_000_000_000_000_000
PERIOD_NS = 100_000_000
Pushed = tuple[Path, Path, WitnessProcess]
SITUATIONS = ("ped_far", "ped_close", "blocked", "clear")


def write(root: Path, key: Path, cycles: range, *, robot_id: str = "amr-7") -> None:
    """Cycles through the real logger: segments of 5 s, a signed checkpoint every second."""
    config = LoggerConfig(
        threaded=False,
        fsync_interval_s=None,
        checkpoint_interval_s=1.0,
        checkpoint_key=load_signer(key),
        max_segment_s=5.0,
    )
    logger = AuditLogger(root, robot_id=robot_id, period_s=0.1, config=config)
    for i in cycles:
        c = logger.cycle(T0_NS + i * PERIOD_NS)
        fill_cycle(c, SITUATIONS[(i // 7) % len(SITUATIONS)])
        c.commit()
    logger.close()


def verify(root: Path, keys: Keys, *extra: str) -> tuple[int, dict[str, Any]]:
    done = run_cli("verify", str(root), "--key", str(keys.robot_pub), "--json", *extra)
    assert done.returncode in (0, 1), done.stderr
    return done.returncode, json.loads(done.stdout)


@pytest.fixture
def pushed(tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]) -> Pushed:
    """A root written in two runs (the first kept as an older copy), pushed to a witness."""
    root = tmp_path / "root"
    write(root, keys.robot_key, range(150))
    older = tmp_path / "older"
    shutil.copytree(root, older)
    write(root, keys.robot_key, range(150, 300))
    w = witness_process()
    push = run_cli("witness", "push", str(root), "--witness", w.url, "--json")
    assert push.returncode == 0, push.stdout + push.stderr
    report = json.loads(push.stdout)["robots"][0]
    assert report["cosigned"] == report["checkpoints"] > 20
    assert report["witness_size"] == 300
    return root, older, w


def _shortened(root: Path, tmp_path: Path, how: str, older: Path) -> Path:
    if how == "rolled back":
        return older
    copy = tmp_path / how.replace(" ", "_")
    shutil.copytree(root, copy)
    segments = sorted((copy / "hot").glob("*.mcap"))
    if how == "newest deleted":
        segments[-1].unlink()
    elif how == "newest two deleted":
        segments[-1].unlink()
        segments[-2].unlink()
    elif how == "newest cut in half":
        data = segments[-1].read_bytes()
        segments[-1].write_bytes(data[: len(data) // 2])
    shutil.rmtree(copy / "witness", ignore_errors=True)  # the attacker removes the store too
    return copy


@pytest.mark.parametrize(
    "how", ["newest deleted", "newest two deleted", "newest cut in half", "rolled back"]
)
def test_a_shortened_log_is_found_only_with_a_witness(
    how: str,
    pushed: Pushed,
    keys: Keys,
    tmp_path: Path,
) -> None:
    root, older, w = pushed
    log = _shortened(root, tmp_path, how, older)
    code, plain = verify(log, keys)
    assert code == 0 and plain["ok"] and not plain["findings"], plain["findings"]
    assert "witness" not in plain
    code, witnessed = verify(log, keys, "--witness", w.url, "--witness-key",
                             keys.witness_verifier.vkey)  # fmt: skip
    assert code == 1
    kinds = [f["kind"] for f in witnessed["findings"]]
    assert kinds == ["truncated_tail"], witnessed["findings"]
    message = witnessed["findings"][0]["message"]
    assert "300 seals" in message and "trace.local/witness" in message and "Z" in message


def test_an_intact_log_gets_its_time_bound(pushed: Pushed, keys: Keys) -> None:
    root, _older, w = pushed
    code, report = verify(root, keys, "--witness", w.url, "--witness-key",
                          keys.witness_verifier.vkey)  # fmt: skip
    assert code == 0 and report["ok"]
    (bound,) = report["witness"]["bounds"]
    assert (bound["tree_size"], bound["cycle"], bound["cosignature_checked"]) == (300, 299, True)
    shown = run_cli("verify", str(root), "--key", str(keys.robot_pub), "--witness", w.url,
                    "--plain")  # fmt: skip
    assert "cycles up to 299" in shown.stdout and "no later than" in shown.stdout
    # the root's own store and a file of a cosigned note say the same
    assert verify(root, keys, "--witness", "local")[0] == 0
    store = (root / "witness" / "amr-7.jsonl").read_text().splitlines()
    note_file = root.parent / "cosigned.note"
    note_file.write_text(json.loads(store[-1])["note"])
    assert verify(root, keys, "--witness", str(note_file))[0] == 0


def test_a_rewritten_history_is_a_fork(pushed: Pushed, keys: Keys, tmp_path: Path) -> None:
    """The same robot key writes another history of 300 cycles: every checkpoint verifies,
    the chain verifies, but the witness saw another tree."""
    _root, _older, w = pushed
    other = tmp_path / "other"
    write(other, keys.robot_key, range(1, 301))
    code, _plain = verify(other, keys)
    assert code == 0
    code, report = verify(other, keys, "--witness", w.url)
    assert code == 1
    assert [f["kind"] for f in report["findings"]] == ["fork"]


def test_a_forged_witnessed_note_vouches_for_nothing(
    pushed: Pushed, keys: Keys, tmp_path: Path
) -> None:
    root, _older, _w = pushed
    store = (root / "witness" / "amr-7.jsonl").read_text().splitlines()
    note = json.loads(store[-1])["note"]
    forged = note.replace("300\n", "301\n", 1)
    path = tmp_path / "forged.note"
    path.write_text(forged)
    code, report = verify(root, keys, "--witness", str(path), "--witness-key",
                          keys.witness_verifier.vkey)  # fmt: skip
    assert code == 1 and [f["kind"] for f in report["findings"]] == ["bad_signature"]


def test_an_unreachable_witness_is_unreadable_input(pushed: Pushed, keys: Keys) -> None:
    import socket

    root, _older, _w = pushed
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    done = run_cli("verify", str(root), "--witness", f"http://127.0.0.1:{port}")
    assert done.returncode == 3 and done.stderr.count("\n") == 1, done.stderr
    assert run_cli("verify", str(root), "--witness", str(root / "no.note")).returncode == 3
    bad_key = run_cli("verify", str(root), "--witness", "local", "--witness-key", "nope")
    assert bad_key.returncode == 2


def test_the_bound_is_the_earliest_cosignature_of_the_largest_tree(
    pushed: Pushed, keys: Keys
) -> None:
    """Pushed again later, the witness cosigns the same tree with a later time; the bound
    ("logged no later than") is the earliest time a witness vouched for that tree."""
    import time

    root, _older, w = pushed
    time.sleep(1.1)  # cosignature times are whole seconds
    assert run_cli("witness", "push", str(root), "--witness", w.url).returncode == 0
    store = (root / "witness" / "amr-7.jsonl").read_text().splitlines()
    stored = [json.loads(line) for line in store if line]
    stamps = sorted({r["timestamp"] for r in stored if r["tree_size"] == 300})
    assert len(stamps) >= 2, stamps  # the same tree, cosigned twice
    code, report = verify(root, keys, "--witness", "local")
    assert code == 0
    (bound,) = report["witness"]["bounds"]
    assert (bound["tree_size"], bound["timestamp"]) == (300, stamps[0])


def test_a_robot_deleted_whole_is_found_when_the_fleet_is_expected(
    tmp_path: Path, keys: Keys, witness_process: Callable[..., WitnessProcess]
) -> None:
    """Two robots in one root, both witnessed; every segment of one (and its store file) is
    deleted. verify --witness alone cannot know it existed; with the fleet's robots named
    (--expect), the witness's tree of it is a truncated_tail."""
    from trace_runtime.tlog.keys import load_public_key
    from trace_runtime.tlog.signed_note import verifier_key

    root = tmp_path / "fleet"
    write(root, keys.robot_key, range(60))
    write(root, keys.robot_key, range(60), robot_id="amr-9")
    other = verifier_key("trace.local/amr-9", load_public_key(keys.robot_pub).raw)
    w = witness_process(keys.robot_vkey, other)
    assert run_cli("witness", "push", str(root), "--witness", w.url).returncode == 0
    for segment in (root / "hot").glob("amr-9_*.mcap"):
        segment.unlink()
    (root / "witness" / "amr-9.jsonl").unlink()
    vkey = keys.witness_verifier.vkey
    code, alone = verify(root, keys, "--witness", w.url, "--witness-key", vkey)
    assert code == 0 and not alone["findings"]  # the gap --expect closes
    code, fleet = verify(root, keys, "--witness", w.url, "--witness-key", vkey,
                         "--expect", "amr-7", "--expect", "trace.local/amr-9")  # fmt: skip
    assert code == 1
    [finding] = fleet["findings"]
    assert (finding["kind"], finding["robot_id"]) == ("truncated_tail", "amr-9")
    assert "60 seals of trace.local/amr-9" in finding["message"]
    assert "holds no segment of robot amr-9" in finding["message"]
    code, unknown = verify(root, keys, "--witness", w.url, "--expect", "amr-5")
    assert code == 0 and any("amr-5" in u for u in unknown["witness"]["unmatched"])
    usage = run_cli("verify", str(root), "--expect", "amr-9")
    assert usage.returncode == 2 and "--witness" in usage.stderr
