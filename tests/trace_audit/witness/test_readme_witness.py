"""The README's witness walkthrough runs as written, in bash, in a fresh directory: keys, a
witness process, a simulated robot submitting to it, verify against it, push, a proof of
one decision and its check. Shorter (1 min, not 10) and on a free port, else word for
word. (Deleting segments against a witness: test_logger_to_witness.py.)"""

from __future__ import annotations

import re
import socket
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]


def _readme_block() -> list[str]:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    block = text.split("A witness makes a log impossible to shorten unseen", 1)[1]
    lines = block.split("```sh", 1)[1].split("```", 1)[0].splitlines()
    return [line.split("  #", 1)[0].strip() for line in lines if line.strip()]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_readme_witness_walkthrough_runs_as_written(tmp_path: Path) -> None:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for name, module in (("trace-audit", "trace_audit.cli"), ("trace-sim", "evaluation.cli")):
        script = bin_dir / name
        script.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m {module} "$@"\n')
        script.chmod(0o755)
    port = str(_free_port())
    lines = [
        line.replace("8080", port).replace("--duration 10m", "--duration 1m")
        for line in _readme_block()
    ]
    assert any(line.endswith("&") for line in lines), lines
    # the witness in the background is stopped however the script ends (its pipes open
    # would keep this test waiting)
    script = "set -e\ntrap 'kill $(jobs -p) 2>/dev/null' EXIT\n" + "\n".join(
        line if not line.startswith("trace-audit witness serve") else line + "\nsleep 3"
        for line in lines
    )
    script += "\n"
    env = {
        "PATH": f"{bin_dir}:/usr/bin:/bin",
        "PYTHONPATH": str(REPO),
        "HOME": str(tmp_path),
    }
    done = subprocess.run(
        ["bash", "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )
    assert done.returncode == 0, (done.stdout[-3000:], done.stderr[-3000:])
    assert "Traceback" not in done.stderr, done.stderr
    assert (tmp_path / "decision.json").is_file()
    assert re.search(r"were logged no\s+later than", done.stdout), done.stdout[-2000:]
