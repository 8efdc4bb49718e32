"""A log's own words in the report's figures: a command, a factor and an entity class that
hold mathtext (``$\\frac{a}{$``), a dollar sign, CJK and emoji, written into the log with the
plain ``mcap`` Writer. ``report`` draws them as the text they are, in a fresh process: exit
0, nothing on stderr (no matplotlib warning with its source path, no traceback)."""

from __future__ import annotations

from pathlib import Path

from tests.outside import cli
from tests.trace_audit.conftest import rewrite_segment, write_log

ODD = {
    "collision_risk": "risk $\\\\frac{a}{$ 人🤖",
    '"STOP"': '"STOP $x$ 停"',
    '"person"': '"人 🚶 $"',
}


def test_odd_text_in_the_figures_reaches_the_page_quietly(tmp_path: Path) -> None:
    plain = write_log(tmp_path / "plain.mcap")

    def odd(message: object) -> bytes:
        data: bytes = message.data  # type: ignore[attr-defined]
        if message.topic.startswith("/trace/"):  # type: ignore[attr-defined]
            text = data.decode()
            for before, after in ODD.items():
                text = text.replace(before, after)
            return text.encode()
        return data

    log = rewrite_segment(plain, tmp_path / "odd.mcap", odd)
    out = tmp_path / "report.html"
    done = cli("report", log, "--t", "104.5", "--out", out)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "", done.stderr
    assert "<svg" in out.read_text(encoding="utf-8")
