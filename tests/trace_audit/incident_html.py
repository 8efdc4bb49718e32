"""Read an incident report back the way a browser's parser would, for the report's tests."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from html.parser import HTMLParser
from typing import Any

# Attributes through which a page can make the browser fetch or run something.
_FETCHING = {"src", "href", "xlink:href", "action", "formaction", "data", "poster", "srcset"}


@dataclass
class ParsedReport:
    tags: list[str] = field(default_factory=list)
    section_ids: list[str] = field(default_factory=list)
    section_text: dict[str, str] = field(default_factory=dict)
    by_id: dict[str, str] = field(default_factory=dict)
    fetches: list[str] = field(default_factory=list)
    """Every fetching attribute value that is not a fragment of the page itself (#...)."""
    handlers: list[str] = field(default_factory=list)
    """Event-handler attributes (onload, onerror, ...): none may appear."""
    scripts: list[tuple[str, str]] = field(default_factory=list)
    """(type, content) of each <script>."""
    svgs: int = 0

    def data(self) -> Any:
        kinds = [kind for kind, _ in self.scripts]
        assert kinds == ["application/json"], kinds
        return json.loads(self.scripts[0][1])


class _Parser(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.out = ParsedReport()
        self._section: str | None = None
        self._ids: list[tuple[str, str, int]] = []  # (id, tag, depth)
        self._depth = 0
        self._script: str | None = None
        self._void = {"meta", "br", "hr", "img", "input", "link", "path", "use", "rect"}

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.out.tags.append(tag)
        values = dict(attrs)
        for name, value in attrs:
            if name in _FETCHING and value is not None and not value.startswith("#"):
                self.out.fetches.append(f"{tag} {name}={value}")
            if name.startswith("on"):
                self.out.handlers.append(f"{tag} {name}")
            if value and "url(" in value and "url(#" not in value:
                self.out.fetches.append(f"{tag} {name}={value}")
        if tag == "svg":
            self.out.svgs += 1
        if tag == "section" and values.get("id"):
            self._section = values["id"]
            self.out.section_ids.append(self._section or "")
            self.out.section_text[self._section or ""] = ""
        if tag == "script":
            self._script = values.get("type") or ""
            self.out.scripts.append((self._script, ""))
        element_id = values.get("id")
        if element_id and tag not in self._void:
            self._ids.append((element_id, tag, self._depth))
            self.out.by_id.setdefault(element_id, "")
        if tag not in self._void:
            self._depth += 1

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.handle_starttag(tag, attrs)
        if tag not in self._void:
            self._depth -= 1

    def handle_endtag(self, tag: str) -> None:
        if tag in self._void:
            return
        self._depth -= 1
        if tag == "section":
            self._section = None
        if tag == "script":
            self._script = None
        while self._ids and self._ids[-1][2] >= self._depth:
            self._ids.pop()

    def handle_data(self, data: str) -> None:
        if self._script is not None:
            kind, content = self.out.scripts[-1]
            self.out.scripts[-1] = (kind, content + data)
            return
        if self._section is not None:
            self.out.section_text[self._section] += data + " "
        for element_id, _, _ in self._ids:
            self.out.by_id[element_id] += data


def parse_report(html: str) -> ParsedReport:
    parser = _Parser()
    parser.feed(html)
    parser.close()
    return parser.out
