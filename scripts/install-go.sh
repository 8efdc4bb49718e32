#!/usr/bin/env bash
# Go and the reference sumdb packages for the witness oracle tests
# (tests/trace_runtime/tlog/test_go_oracle.py): Debian's `golang-go` and `golang-golang-x-mod-dev`.
# Installs them when missing and this user may (root with apt-get); otherwise says why, and
# the oracle tests skip with that reason visible. Never fails the caller.
set -uo pipefail
mod=/usr/share/gocode/src/golang.org/x/mod/sumdb
if command -v go >/dev/null 2>&1 && [ -d "$mod/note" ] && [ -d "$mod/tlog" ]; then
  exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "install-go: go or golang.org/x/mod not found and cannot be installed here (needs root and apt-get); Go oracle tests will skip" >&2
  exit 0
fi
echo "install-go: installing Debian's golang-go and golang-golang-x-mod-dev for the Go oracle tests ..." >&2
log=$(mktemp)
if ! { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends golang-go golang-golang-x-mod-dev; } >"$log" 2>&1; then
  tail -5 "$log" >&2
  echo "install-go: install failed (above); Go oracle tests will skip" >&2
fi
rm -f "$log"
exit 0
