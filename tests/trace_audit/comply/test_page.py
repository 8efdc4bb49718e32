"""The conformity evidence page (``comply --html``): a section per clause with each check,
its evidence, its verdict and the command that reproduces it; nothing from the root or the
profile can open a tag; and in headless Chromium it opens without a console error, is not
blank, and prints to A4 (skipped, with the reason, when Chromium is not installed)."""

from __future__ import annotations

import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import pytest

from tests.trace_audit.browser import find_chromium, run_chromium
from tests.trace_audit.comply.conftest import comply, trusted
from tests.trace_audit.incident.test_page_browser import _non_blank
from tests.trace_audit.witness.conftest import Keys
from trace_audit.comply import load_profile

CHROMIUM = find_chromium()
_needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not found: run scripts/install-browser.sh (Debian's chromium)",
)


class _Checks(HTMLParser):
    """The sections and the checks (name, verdict) a page holds."""

    def __init__(self) -> None:
        super().__init__()
        self.sections: list[str] = []
        self.checks: list[tuple[str, str]] = []
        self.scripts: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "section":
            self.sections.append(a.get("id") or "")
        if tag == "div" and a.get("data-check"):
            self.checks.append((a["data-check"] or "", a.get("data-verdict") or ""))
        if tag == "script":
            self.scripts.append(a.get("type") or "")


@pytest.fixture(scope="module")
def pages(
    tmp_path_factory: pytest.TempPathFactory, witnessed_root: Path, comply_keys: Keys
) -> dict[str, Path]:
    work = tmp_path_factory.mktemp("pages")
    root = work / "root"
    shutil.copytree(witnessed_root, root)
    out = {}
    for profile, where, args in (
        ("machinery-2023-1230", root, (*trusted(comply_keys), "--adopt")),
        ("ai-act-art12", witnessed_root, ()),  # no key, not adopted: clauses not met
    ):
        page = work / f"{profile}.html"
        done = comply(where, profile, *args, "--html", str(page))
        assert page.is_file(), done.stderr
        out[profile] = page
    return out


def test_the_page_has_every_clause_check_and_verdict(pages: dict[str, Path]) -> None:
    for profile, page in pages.items():
        text = page.read_text(encoding="utf-8")
        parsed = _Checks()
        parsed.feed(text)
        clauses = load_profile(profile).clauses
        assert parsed.sections == [
            "clauses",
            *(f"clause-{i}" for i in range(1, len(clauses) + 1)),
            "reproduce",
            "limits",
        ]
        assert [name for name, _ in parsed.checks] == [n for c in clauses for n in c.checks]
        assert parsed.scripts == ["application/json"]  # data only, never run
        assert "--profile " + profile in text and "does not certify" in text
    machinery = _Checks()
    machinery.feed(pages["machinery-2023-1230"].read_text(encoding="utf-8"))
    assert {v for _, v in machinery.checks} == {"met"}
    ai_act = _Checks()
    ai_act.feed(pages["ai-act-art12"].read_text(encoding="utf-8"))
    assert ("signed", "not met") in ai_act.checks and ("retention", "not met") in ai_act.checks
    assert "<strong>Fix:</strong>" in pages["ai-act-art12"].read_text(encoding="utf-8")


def test_a_hostile_profile_cannot_open_a_tag(witnessed_root: Path, tmp_path: Path) -> None:
    hostile = tmp_path / "hostile.toml"
    hostile.write_text('name = "<script>alert(1)</script>"\n[[clause]]\n'
                       'reference = "</section><script>x()</script>"\n'
                       'summary = "<img src=x onerror=y()>"\nchecks = ["chain"]\n')  # fmt: skip
    page = tmp_path / "page.html"
    comply(witnessed_root, str(hostile), "--html", str(page))
    parsed = _Checks()
    parsed.feed(page.read_text(encoding="utf-8"))
    assert parsed.scripts == ["application/json"]
    assert "<img" not in page.read_text(encoding="utf-8")


@_needs_chromium
def test_the_page_opens_in_chromium_without_console_errors_and_prints_to_a4(
    pages: dict[str, Path], tmp_path: Path
) -> None:
    assert CHROMIUM is not None
    for page in pages.values():
        shot = tmp_path / f"{page.stem}.png"
        done = run_chromium(
            CHROMIUM, page, tmp_path, f"--screenshot={shot}", "--window-size=1100,1800"
        )
        assert done.returncode == 0, done.stderr[-2000:]
        assert done.console == []
        colours, inked = _non_blank(shot)
        assert colours > 50 and inked > 0.03, (colours, inked)
    pdf = tmp_path / "page.pdf"
    done = run_chromium(CHROMIUM, pages["machinery-2023-1230"], tmp_path,
                        f"--print-to-pdf={pdf}", "--no-pdf-header-footer")  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF-")
    assert re.search(rb"/MediaBox\s*\[0 0 59[45]\.?\d* 84[12]\.?\d*\]", data)
