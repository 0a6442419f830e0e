#!/usr/bin/env bash
# Install PostgreSQL and PostGIS (Debian packages) for the landmark repository tests and
# the PostGIS scale benchmark.  Does nothing when both are already installed.
set -euo pipefail
if ls /usr/share/postgresql/*/extension/postgis.control >/dev/null 2>&1 \
    && ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1; then
    echo "[install-postgis] PostgreSQL and PostGIS already installed"
    exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq postgresql
version=$(ls /usr/lib/postgresql/ | sort -n | tail -1)
$SUDO apt-get install -y -qq postgis "postgresql-${version}-postgis-3"
echo "[install-postgis] installed: $(ls /usr/lib/postgresql/)"
