"""A ``catalog.json`` just under the side-file read cap, full of rows naming files that are not
there (ghost rows, which every reader drops), costs ``catalog``, ``explain`` and
``catalog --refresh`` no more than a bounded amount of memory: measured from the outside, as
the peak resident size of the CLI's process."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.outside import REPO
from tests.trace_audit.conftest import write_log
from trace_runtime.boundary import SIDE_FILE_BYTES
from trace_runtime.tiers.catalog import refresh_catalog

PEAK_MB = 256
INSIDE_T = "105.0"  # a time inside the fixture log (t = 100 s .. 110 s)

_PEAK = """import resource, subprocess, sys
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
print(done.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, done.stderr)"""


def _peak_mb(*args: str | Path) -> tuple[int, float, str]:
    """Exit code, peak resident size in MB and stderr of ``trace-audit ARGS``, measured by a
    parent of its own (this test process's other children would count too)."""
    done = subprocess.run(
        [sys.executable, "-c", _PEAK, sys.executable, "-m", "trace_audit.cli", *map(str, args)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
    )
    code, kib, stderr = done.stdout.split(" ", 2)
    return int(code), int(kib) / 1024, stderr


def _ghost_catalog(root: Path, *, short: bool) -> bytes:
    """The root's own catalog plus ghost rows up to just under the read cap, written with the
    standard library's json: full rows as the writer makes them, or rows of one-letter
    strings (the most rows, so the most objects, the cap allows)."""
    body = json.loads((root / "catalog.json").read_text(encoding="utf-8"))
    row = body["segments"][0]
    if short:
        row = {k: v[:1] if isinstance(v, str) else v for k, v in row.items()}
    size, i = len(json.dumps(body)), 0
    while size < SIDE_FILE_BYTES - 4096:
        ghost = dict(row, path=f"hot/g{i}.mcap", segment=100 + i)
        body["segments"].append(ghost)
        size, i = size + len(json.dumps(ghost)) + 2, i + 1
    data = json.dumps(body).encode()
    assert SIDE_FILE_BYTES - 1_000_000 < len(data) <= SIDE_FILE_BYTES, len(data)
    return data


@pytest.mark.parametrize("short", [False, True], ids=["full-rows", "short-rows"])
def test_a_catalog_of_ghost_rows_under_the_cap_costs_bounded_memory(
    tmp_path: Path, short: bool
) -> None:
    root = write_log(tmp_path / "root", robot_id="r1", max_segment_s=3.0)
    refresh_catalog(root)
    real = (root / "catalog.json").read_bytes()
    ghosts = _ghost_catalog(root, short=short)
    for args in (
        ("catalog", root),
        ("explain", root, "--t", INSIDE_T),
        ("catalog", root, "--refresh"),
    ):
        (root / "catalog.json").write_bytes(ghosts)
        code, peak, stderr = _peak_mb(*args, "--plain")
        assert code == 0 and "Traceback" not in stderr, stderr
        assert peak <= PEAK_MB, (args[0], f"{peak:.0f} MB")
    assert json.loads((root / "catalog.json").read_bytes()) == json.loads(real)
