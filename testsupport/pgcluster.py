"""A throwaway PostgreSQL + PostGIS cluster for tests (and the scale benchmark).

initdb into a temporary directory, pg_ctl start on a free 127.0.0.1 port with the unix
socket in that directory; as root the cluster runs as the ``postgres`` user.  Missing
binaries or PostGIS -> ``pytest.skip`` with the reason (install: scripts/install-postgis.sh).
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager

import psycopg
import pytest


def _binary(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    candidates = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    return candidates[-1] if candidates else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _skip(reason: str) -> None:
    print(f"\nSKIP PostGIS tests: {reason}")
    pytest.skip(reason)


@contextmanager
def throwaway_cluster() -> Iterator[str]:
    """Yield the URL of the ``postgres`` database of a fresh cluster; stop and delete it."""
    initdb, pg_ctl = _binary("initdb"), _binary("pg_ctl")
    if not initdb or not pg_ctl:
        _skip("PostgreSQL server binaries (initdb, pg_ctl) are not installed; "
              "run scripts/install-postgis.sh")
    assert initdb and pg_ctl
    prefix: list[str] = []
    if os.geteuid() == 0:
        try:
            user = pwd.getpwnam("postgres")
        except KeyError:
            _skip("running as root and there is no 'postgres' user to run the server")
        # runuser is in /usr/sbin, which a user's PATH may leave out (env -i, sudo -E)
        runuser = shutil.which("runuser", path=os.pathsep.join(
            [os.environ.get("PATH", ""), "/usr/sbin", "/sbin"]))
        if runuser is None:
            _skip("running as root and runuser (util-linux) is not installed")
        assert runuser
        prefix = [runuser, "-u", "postgres", "--"]
    root = tempfile.mkdtemp(prefix="lmc-pg-")
    data = os.path.join(root, "data")
    if prefix:
        os.chown(root, user.pw_uid, user.pw_gid)
    port = _free_port()
    log = os.path.join(root, "server.log")
    try:
        subprocess.run([*prefix, initdb, "-D", data, "-U", "postgres", "--auth=trust",
                        "-E", "UTF8", "--no-sync"], check=True, capture_output=True)
        opts = (f"-p {port} -k {root} -c listen_addresses=127.0.0.1 -c fsync=off "
                "-c synchronous_commit=off -c full_page_writes=off")
        subprocess.run([*prefix, pg_ctl, "-D", data, "-l", log, "-o", opts, "-w", "start"],
                       check=True, capture_output=True, timeout=60)
        url = f"postgresql://postgres@127.0.0.1:{port}/postgres"
        try:
            with psycopg.connect(url, autocommit=True) as conn:
                conn.execute("CREATE EXTENSION IF NOT EXISTS postgis")
        except psycopg.Error as err:
            _skip(f"PostGIS is not available in this PostgreSQL ({err}); "
                  "run scripts/install-postgis.sh")
        yield url
    finally:
        if os.path.exists(os.path.join(data, "postmaster.pid")):
            subprocess.run([*prefix, pg_ctl, "-D", data, "-m", "immediate", "stop"],
                           capture_output=True, timeout=60, check=False)
        shutil.rmtree(root, ignore_errors=True)
