#!/usr/bin/env bash
# System packages that some tests need, from Debian's archive: chromium (the dashboard's
# browser test) and PostgreSQL + PostGIS (the landmark repository tests, which start their
# own throwaway cluster).  Those tests skip, with the reason printed, where the packages
# cannot be installed.  Idempotent; never fails the run by itself.
set -uo pipefail
cd "$(dirname "$0")/.."
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "[ci] not root or no apt-get: tests needing chromium or PostGIS will skip"
    exit 0
fi
export DEBIAN_FRONTEND=noninteractive
if ! command -v chromium >/dev/null 2>&1; then
    echo "[ci] apt-get install chromium"
    apt-get update -qq >/dev/null 2>&1 || true
    apt-get install -y -qq --no-install-recommends chromium >/dev/null 2>&1 \
        || echo "[ci] chromium could not be installed; the browser test will skip"
fi
bash scripts/install-postgis.sh || echo "[ci] PostGIS could not be installed; its tests will skip"
exit 0
