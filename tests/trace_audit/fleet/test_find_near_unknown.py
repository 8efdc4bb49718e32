"""find --near for a class the index holds but at no known distance says why there are no
rows (found from outside: "0 rows" for boxes logged without a distance in the belief)."""

from __future__ import annotations

from pathlib import Path

from tests.outside import cli
from trace_runtime import AuditLogger, Entity, Perception, Pose
from trace_runtime.testing import synthetic_cycle


def test_a_class_seen_at_no_known_distance_is_named(tmp_path: Path) -> None:
    root = tmp_path / "log"
    with AuditLogger(root, robot_id="r", period_s=0.1) as logger:
        for i in range(20):
            p, b, a, e = synthetic_cycle(i)
            box = Entity(
                id="box_1", cls="box", confidence={"box": 0.9}, pose=Pose(position=(0.9, 0, 0))
            )
            p = Perception(entities=[*p.entities, box])
            logger.log_cycle(i * 100_000_000, perception=p, belief=b, action=a, execution=e)
    assert cli("index", root, "--out", tmp_path / "idx").returncode == 0
    done = cli("find", tmp_path / "idx", "--near", "box")
    assert done.returncode == 0, done.stderr
    assert "20 box entit(ies) are indexed, none at a known distance" in done.stderr
    assert "0 decisions" in done.stdout
    # a class with distances gives rows and no such line
    found = cli("find", tmp_path / "idx", "--near", "person")
    assert found.returncode == 0 and "known distance" not in found.stderr
