#!/usr/bin/env bash
# SoftHSM2, a PKCS#11 token in software, for the tests of checkpoint keys held in a token
# (Debian's `softhsm2`). Installs it when missing and this user may (root with apt-get);
# otherwise says why, and the token tests skip with that reason visible. Never fails the caller.
set -uo pipefail
for lib in /usr/lib/softhsm/libsofthsm2.so /usr/lib/*/softhsm/libsofthsm2.so; do
  if [ -e "$lib" ]; then exit 0; fi
done
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "install-softhsm: SoftHSM2 not found and cannot be installed here (needs root and apt-get); token tests will skip" >&2
  exit 0
fi
echo "install-softhsm: installing Debian's softhsm2 for the token tests ..." >&2
log=$(mktemp)
if ! { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends softhsm2; } >"$log" 2>&1; then
  tail -5 "$log" >&2
  echo "install-softhsm: install failed (above); token tests will skip" >&2
fi
rm -f "$log"
exit 0
