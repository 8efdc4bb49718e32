"""On a wall-clock log a plain number is seconds since 1970: ``--t 60.0`` is a minute
after midnight on 1 January 1970, far before the log. Whoever types it meant 60 s into the
log; every command that reads a time says how to write that (``+60``), once, from the
same place; a time of day that misses the log gets no such hint."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.outside import cli, one_line
from tests.trace_audit.conftest import write_log

T0_WALL_NS = 1_777_874_400 * 1_000_000_000  # 2026-05-04T06:00:00Z
RULES = '[[rule]]\nname = "keeps_away"\nstl = "always(nearest.person >= 0.5)"\n'


@pytest.fixture(scope="module")
def wall(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("wall")
    (where / "rules.toml").write_text(RULES, encoding="utf-8")
    return write_log(where / "wall.mcap", t0_ns=T0_WALL_NS)


@pytest.mark.parametrize(
    ("args", "offset"),
    [
        (("explain", "--t", "60.0"), "+60"),
        (("explain", "--t", "0.5"), "+0.5"),
        (("export", "--t", "2"), "+2"),
        (("report", "--t", "2"), "+2"),
        (("check", "--from", "2", "--to", "5"), "+2"),
        (("timeline", "--to", "5"), "+5"),
    ],
    ids=lambda v: " ".join(v) if isinstance(v, tuple) else v,
)
def test_a_small_number_on_a_wall_clock_gets_the_offset_hint(
    wall: Path, tmp_path: Path, args: tuple[str, ...], offset: str
) -> None:
    extra: tuple[str, ...] = ()
    if args[0] in ("export", "report"):
        extra = ("--out", str(tmp_path / ("out.mcap" if args[0] == "export" else "r.html")))
    if args[0] == "check":
        extra = ("--rules", str(wall.parent / "rules.toml"))
    done = cli(args[0], wall, *args[1:], *extra)
    one_line(done, 2, "1970-01-01", f"{offset} counts from the log's start")


def test_a_time_of_day_outside_the_log_gets_no_offset_hint(wall: Path) -> None:
    done = cli("explain", wall, "--t", "2026-05-05T06:00:00Z")
    one_line(done, 2, "outside the log's range")
    assert "counts from the log's start" not in done.stderr
