#!/usr/bin/env bash
# System packages that some tests need, from Debian's archive: chromium (dashboard browser
# test) and PostgreSQL + PostGIS (landmark repository tests).  Tests that need them skip,
# with the reason printed, where they cannot be installed.  Idempotent; quiet.
set -uo pipefail
want=()
command -v chromium >/dev/null 2>&1 || want+=(chromium)
for pkg in "$@"; do want+=("$pkg"); done
if [ -f scripts/system-packages.txt ]; then
    while read -r pkg; do
        [ -n "$pkg" ] && [ "${pkg#\#}" = "$pkg" ] && ! dpkg -s "$pkg" >/dev/null 2>&1 && want+=("$pkg")
    done < scripts/system-packages.txt
fi
[ ${#want[@]} -eq 0 ] && exit 0
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "[ci] cannot install ${want[*]} (not root or no apt-get); tests needing them will skip"
    exit 0
fi
echo "[ci] apt-get install ${want[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq >/dev/null 2>&1 || true
apt-get install -y -qq --no-install-recommends "${want[@]}" >/dev/null 2>&1 \
    || echo "[ci] apt-get install failed; tests needing ${want[*]} will skip"
exit 0
