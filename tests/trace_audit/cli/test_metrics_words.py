"""``metrics`` on a user's own log speaks of that log, not of the paper's tables: no
"Table II", no "Method TRACE (this log)" row; the JSON keys scripts read stay as they are."""

from __future__ import annotations

import json
from pathlib import Path

from tests.outside import cli
from tests.trace_audit.conftest import write_log


def test_the_headline_says_what_the_log_shows(tmp_path: Path) -> None:
    log = write_log(tmp_path / "root", robot_id="amr-7")
    done = cli("metrics", log, "--plain", "--by", "hour")
    assert done.returncode == 0, done.stderr
    for paper in ("Table II", "Table III", "Method", "TRACE (this log)"):
        assert paper not in done.stdout, done.stdout
    assert "Auditability metrics of the 100 decisions" in done.stdout, done.stdout
    assert "Per hour" in done.stdout, done.stdout
    keys = json.loads(cli("metrics", log, "--json", "--by", "hour").stdout)
    assert {"overall", "groups", "table_iii", "by"} <= set(keys), sorted(keys)
