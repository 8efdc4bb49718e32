"""The incident report in a real browser: headless Chromium opens it without a console error,
its screenshot is not blank, and it prints to a multi-page A4 PDF.

Skipped, with the reason shown, when Chromium is not installed (``scripts/install-browser.sh``
installs Debian's ``chromium``; ``scripts/test.sh`` runs it).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.trace_audit.browser import find_chromium, run_chromium
from trace_audit.incident import build_report, write_report

CHROMIUM = find_chromium()
pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not found: run scripts/install-browser.sh (Debian's chromium)",
)


@pytest.fixture(scope="module")
def report_page(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from sim.runner import RunConfig, run
    from trace_audit.transitions import why

    work = tmp_path_factory.mktemp("browser")
    log = work / "run.mcap"
    run(RunConfig(out=log, scenario="all", cycles=100, seed=42))
    first_stop = why(log, "STOP").transitions[0].t_ns
    return write_report(build_report(log, t=first_stop), work / "incident.html")


def _non_blank(png: Path) -> tuple[int, float]:
    """(distinct colours, share of pixels that are not near-white) of a screenshot."""
    from PIL import Image

    with Image.open(png) as image:
        rgb = image.convert("RGB")
        colours = rgb.getcolors(maxcolors=1 << 20) or []
        inked = sum(n for n, (r, g, b) in colours if min(r, g, b) < 235)
        return len(colours), inked / (rgb.width * rgb.height)


def test_the_report_opens_without_console_errors_and_is_not_blank(
    report_page: Path, tmp_path: Path
) -> None:
    assert CHROMIUM is not None
    shot = tmp_path / "report.png"
    done = run_chromium(
        CHROMIUM, report_page, tmp_path, f"--screenshot={shot}", "--window-size=1100,2400"
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.console == []
    colours, inked = _non_blank(shot)
    assert colours > 200 and inked > 0.05, (colours, inked)


def test_the_console_check_sees_a_page_error(tmp_path: Path) -> None:
    """The check above can fail: a page with a script error is caught by it."""
    assert CHROMIUM is not None
    page = tmp_path / "broken.html"
    page.write_text("<!DOCTYPE html><p>x</p><script>notDefined();</script>", encoding="utf-8")
    done = run_chromium(CHROMIUM, page, tmp_path, f"--screenshot={tmp_path / 'b.png'}")
    assert any("notDefined" in line for line in done.console), done.stderr[-2000:]


def test_the_report_prints_to_a_multi_page_pdf(report_page: Path, tmp_path: Path) -> None:
    assert CHROMIUM is not None
    pdf = tmp_path / "report.pdf"
    done = run_chromium(
        CHROMIUM, report_page, tmp_path, f"--print-to-pdf={pdf}", "--no-pdf-header-footer"
    )
    assert done.returncode == 0, done.stderr[-2000:]
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF-")
    pages = len(re.findall(rb"/Type\s*/Page\b", data))
    assert pages >= 3, pages
    # A4 is 595 x 842 points; Chromium writes each page's MediaBox
    assert re.search(rb"/MediaBox\s*\[0 0 59[45]\.?\d* 84[12]\.?\d*\]", data), data[:4000]
