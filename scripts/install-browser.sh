#!/usr/bin/env bash
# Headless Chromium for the report's browser tests (Debian's `chromium` package). Installs it
# when missing and this user may (root with apt-get); otherwise says why, and the browser
# tests skip with that reason visible. Never fails the caller.
set -uo pipefail
if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then
  exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "install-browser: chromium not found and cannot be installed here (needs root and apt-get); browser tests will skip" >&2
  exit 0
fi
echo "install-browser: installing Debian's chromium for the report's browser tests ..." >&2
log=$(mktemp)
if ! { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends chromium; } >"$log" 2>&1; then
  tail -5 "$log" >&2
  echo "install-browser: chromium install failed (above); browser tests will skip" >&2
fi
rm -f "$log"
exit 0
