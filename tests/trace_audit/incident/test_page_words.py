"""The report's words are people's: verify's notes and findings named as an investigator
would (its kinds stay in data attributes, for scripts), and each thing said once. A log with
dropped cycles (declared by the seal) and no --key, reported from outside."""

from __future__ import annotations

import html
import re

import pytest

from tests.outside import cli
from tests.trace_audit.conftest import write_log
from trace_runtime.verification.report import KIND_WORDS


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> str:
    where = tmp_path_factory.mktemp("words")
    log = write_log(where / "skip.mcap", skip=lambda i: i in (12, 13, 14))
    out = where / "report.html"
    done = cli("report", log, "--t", "104.5", "--out", out)
    assert done.returncode == 0, done.stderr
    return out.read_text(encoding="utf-8")


def _visible(page: str) -> str:
    """The page's text as a reader sees it: no figures, tags, attributes or the JSON."""
    body = re.sub(r"<svg.*?</svg>|<script.*?</script>|<pre.*?</pre>", "", page, flags=re.S)
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", body)).split())


def test_verify_kinds_are_said_in_words_and_kept_as_attributes(page: str) -> None:
    text = _visible(page)
    for kind in ("declared_gap", "signatures_unchecked"):
        assert kind not in text, text
        words = KIND_WORDS[kind]
        assert f'data-kind="{kind}">{words[0].upper()}{words[1:]}: ' in page, words


def test_where_the_metrics_are_defined_is_said_once(page: str) -> None:
    text = _visible(page)
    assert text.count("docs/metrics.md") == 1, text


def test_every_kind_verify_can_give_has_words() -> None:
    from typing import get_args

    from trace_runtime.verification.report import FindingKind, NoteKind

    kinds = {*get_args(FindingKind), *get_args(NoteKind)}
    assert kinds == set(KIND_WORDS), kinds ^ set(KIND_WORDS)
