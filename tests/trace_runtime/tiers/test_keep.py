"""``compliance.toml``: adopting profiles into a root (a second one adds, the same one
again replaces, the strictest decides) and the periods compaction is held to."""

from __future__ import annotations

from pathlib import Path

import pytest

from trace_runtime.errors import LogReadError, UsageError
from trace_runtime.tiers.durations import DAY_NS
from trace_runtime.tiers.keep import KeptProfile, adopt_profile, read_keep, resolve_periods


def test_adopting_adds_replaces_and_the_strictest_decides(tmp_path: Path) -> None:
    assert read_keep(tmp_path) is None
    adopt_profile(tmp_path, KeptProfile("a", 184, True))
    adopt_profile(tmp_path, KeptProfile("b", 1827, False))
    keep = adopt_profile(tmp_path, KeptProfile("a", 200, True))
    assert read_keep(tmp_path) == keep
    assert [p.name for p in keep.profiles] == ["b", "a"]
    assert keep.keep_ns == 1827 * DAY_NS and keep.full_detail_ns == 200 * DAY_NS


def test_periods_rise_to_the_profile_and_a_shorter_request_is_refused(tmp_path: Path) -> None:
    keep = adopt_profile(tmp_path, KeptProfile("law", 10, True))
    periods = {"default_older_than_ns": DAY_NS, "override": False}
    assert resolve_periods(
        tmp_path,
        keep,
        tier="warm",
        older_than_ns=None,
        retention_ns=DAY_NS,
        retention_default=True,
        **periods,
    ) == (10 * DAY_NS, 10 * DAY_NS)
    # cold compaction is lossless: its age is not held, only retention is
    assert resolve_periods(
        tmp_path,
        keep,
        tier="cold",
        older_than_ns=0,
        retention_ns=None,
        retention_default=False,
        **periods,
    ) == (0, None)
    with pytest.raises(UsageError, match="--retention 9d would delete younger ones"):
        resolve_periods(
            tmp_path,
            keep,
            tier="cold",
            older_than_ns=0,
            retention_ns=9 * DAY_NS,
            retention_default=False,
            **periods,
        )
    assert resolve_periods(
        tmp_path,
        keep,
        tier="warm",
        older_than_ns=0,
        retention_ns=0,
        retention_default=False,
        default_older_than_ns=DAY_NS,
        override=True,
    ) == (0, 0)


@pytest.mark.parametrize(
    "text",
    [
        '[[profile]]\nname = "x"\nkeep_days = "5y"\n',
        '[[profile]]\nname = "../x"\nkeep_days = 5\n',
        '[[profile]]\nname = "x"\nkeep_days = 5\nfull_detail = "yes"\n',
        "profile = 3\n",
    ],
)
def test_a_file_of_the_wrong_shape_is_unreadable_input(tmp_path: Path, text: str) -> None:
    (tmp_path / "compliance.toml").write_text(text)
    with pytest.raises(LogReadError):
        read_keep(tmp_path)
