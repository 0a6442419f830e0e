"""Subprocess for the kill test: import a map and stop (sleep) once part is written.

Usage: python import_worker.py DB MAP [BULK_ROWS].  After the first chunk of rows is inside the open
transaction it prints ``HALFWAY`` and sleeps, so the test can SIGKILL it mid-import.
"""

from __future__ import annotations

import sys
import time

from companion.landmarks import sqlite_repo
from companion.landmarks.repository import import_map
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository


def _halfway(done: int) -> None:
    print(f"HALFWAY {done}", flush=True)
    time.sleep(120)


if __name__ == "__main__":
    if len(sys.argv) > 3:
        sqlite_repo.BULK_ROWS = int(sys.argv[3])
    with SqliteLandmarkRepository(sys.argv[1]) as repo:
        import_map(repo, sys.argv[2], progress=_halfway)
    print("FINISHED", flush=True)
