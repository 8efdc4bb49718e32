"""Disk decay is damage, not tampering: one bad chunk is reported where it is, everything
else is still read and verified, and every command still answers."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.trace_audit.conftest import write_log
from trace_audit.cli import app
from trace_audit.verify import verify_log
from trace_runtime import open_log, open_segment


def _decay(path: Path, which: int) -> int:
    """Flip one byte inside the compressed records of the ``which``-th chunk."""
    offset = open_segment(path).chunks()[which].offset
    data = bytearray(path.read_bytes())
    data[offset + 80] ^= 0x10
    path.write_bytes(bytes(data))
    return offset


@pytest.mark.parametrize("finished", [True, False], ids=["finished", "crashed"])
def test_one_decayed_chunk_is_one_damaged_finding_and_the_rest_verifies(
    tmp_path: Path, finished: bool
) -> None:
    path = write_log(tmp_path / "run.mcap", finish=finished)
    cycles = [c.cycle for c in open_log(path).iter_cycles()]
    offset = _decay(path, 40)
    report = verify_log(path)
    assert [f.kind for f in report.findings] == ["damaged"], [f.message for f in report.findings]
    (finding,) = report.findings
    assert f"chunk at offset {offset}" in finding.message
    lost = [c for c in cycles if finding.covers(c)]
    assert len(lost) == 1
    read = [c.cycle for c in open_log(path).iter_cycles()]
    assert read == [c for c in cycles if c not in lost]
    assert report.checkpoints_valid == report.checkpoints


def test_every_command_still_answers_on_a_decayed_log(tmp_path: Path) -> None:
    path = write_log(tmp_path / "run.mcap")
    _decay(path, 40)
    runner = CliRunner()
    for args in (["info"], ["metrics"], ["why", "--action", "STOP"], ["timeline"]):
        result = runner.invoke(app, [args[0], str(path), *args[1:], "--plain"])
        assert result.exit_code == 0, (args, result.output)
    assert runner.invoke(app, ["verify", str(path), "--plain"]).exit_code == 1
