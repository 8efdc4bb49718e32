"""Headless Chromium for the report's browser tests: open a page, screenshot it, print it.

Each run gets a fresh profile directory and the flags that keep Chromium off the network
(no background networking, component updates, sync or QUIC). Console messages (script
errors, CSP violations, failed loads) are read from Chromium's own log on stderr.
"""

from __future__ import annotations

import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--enable-logging=stderr",
    "--v=0",
)
TIMEOUT_S = 90


def find_chromium() -> str | None:
    """The Chromium binary, or None when this machine has none (scripts/install-browser.sh)."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


@dataclass(frozen=True)
class BrowserRun:
    returncode: int
    console: list[str]
    """Console messages the page produced (each Chromium ``CONSOLE`` log line)."""
    stderr: str


def run_chromium(binary: str, page: Path, work: Path, *action: str) -> BrowserRun:
    """Open ``page`` in a fresh profile under ``work`` and do ``action`` (e.g.
    ``--screenshot=...``)."""
    profile = work / f"profile-{len(list(work.glob('profile-*')))}"
    done = subprocess.run(
        [binary, *FLAGS, f"--user-data-dir={profile}", *action, page.resolve().as_uri()],
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        check=False,
    )
    console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
    return BrowserRun(done.returncode, console, done.stderr)
