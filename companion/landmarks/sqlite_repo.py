"""The on-board landmark store: SQLite with WAL, foreign keys, a versioned schema with
migrations (``PRAGMA user_version``) and an R*Tree spatial index.

Positions are indexed by ``landmarks_rtree``, an R*Tree of *buckets*: a bulk load
stores landmarks in Morton (Z-curve) order, so consecutive ``rid`` values are spatial
neighbours, and every run of up to ``BUCKET`` consecutive rows gets one R*Tree entry
(its bounding box, ``rid_lo``, ``rid_hi``).  That is the leaf level of a packed R-tree:
an area query finds the buckets whose boxes overlap it, then range-scans their rows.
It needs ``BUCKET`` times fewer R*Tree inserts than one entry per point (an R*Tree
insert costs ~12 us), which is what makes imports of >= 50,000 records/s possible.
The table's CHECKs list allowed values as ``x = 'a' OR x = 'b' ...``: SQLite (3.40)
builds a temporary index for an ``IN (...)`` list of three or more values on every row
it writes, which cost ~3 us a row, more than the row itself (schema version 4).
Invariant: every row lies inside the box of a bucket whose rid range contains it
(rows are only ever deleted or added in new buckets with fresh rids; positions never
change in place).  Buckets emptied by deletions stay, harmless, until a ``VACUUM``-like
rebuild (not needed on board, where maps are replaced whole).
The R*Tree stores 32-bit floats rounded outwards, so queries re-check exact coordinates.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from companion.core.landmark import BBox, spatial_order
from companion.core.landmark_rows import (
    APPEARANCE_COLUMNS,
    COLUMNS,
    LandmarkRows,
)
from companion.errors import CompanionError, InputError
from companion.landmarks.repository import Progress
from companion.landmarks.sql_repo import SqlLandmarkRepository

_ID_INDEX = "CREATE UNIQUE INDEX landmarks_id ON landmarks (id)"
_NAME_INDEX = "CREATE INDEX landmarks_name ON landmarks (name)"
#: Imports at least this large (and larger than the table) drop the id and name indexes
#: and build them again afterwards (a sort) instead of updating them row by row.
BULK_ROWS = 50_000

#: Consecutive rows per R*Tree entry (see the module docstring).
BUCKET = 16

#: Columns of ``landmarks`` whose definition has not changed since version 1.
_PLACE_AND_SIZE = """lat_deg REAL NOT NULL CHECK (lat_deg BETWEEN -90 AND 90),
            lon_deg REAL NOT NULL CHECK (lon_deg BETWEEN -180 AND 180),
            alt_m REAL NOT NULL,
            width_m REAL NOT NULL CHECK (width_m > 0),
            height_m REAL NOT NULL CHECK (height_m > 0),
            facing_deg REAL CHECK (facing_deg >= 0 AND facing_deg < 360),"""

#: MIGRATIONS[k] brings a database from schema version k to k + 1.
MIGRATIONS: tuple[tuple[str, ...], ...] = (
    (  # 0 -> 1: landmarks and their spatial index
        f"""CREATE TABLE landmarks (
            rid INTEGER PRIMARY KEY,
            id TEXT NOT NULL,
            name TEXT NOT NULL,
            category TEXT NOT NULL
                CHECK (category IN ('signpost', 'wall_image', 'logo', 'other')),
            {_PLACE_AND_SIZE}
            status TEXT NOT NULL DEFAULT 'candidate'
                CHECK (status IN ('candidate', 'approved', 'rejected')),
            status_reason TEXT NOT NULL DEFAULT '',
            distinctiveness REAL, flatness REAL, static REAL, impact REAL
        )""",
        _ID_INDEX,
        "CREATE VIRTUAL TABLE landmarks_rtree USING rtree(rid, min_lon, max_lon, min_lat, max_lat)",
    ),
    (  # 1 -> 2: appearance images in the database, 3-D points and sightings, name index
        "ALTER TABLE landmarks ADD COLUMN points_json TEXT",
        "ALTER TABLE landmarks ADD COLUMN sightings_json TEXT",
        _NAME_INDEX,
        """CREATE TABLE appearances (
            rid INTEGER PRIMARY KEY REFERENCES landmarks (rid) ON DELETE CASCADE,
            media_type TEXT NOT NULL,
            data BLOB NOT NULL,
            box_x INTEGER, box_y INTEGER, box_w INTEGER, box_h INTEGER
        )""",
    ),
    (  # 2 -> 3: one R*Tree entry per bucket of consecutive rows instead of per point
        "ALTER TABLE landmarks_rtree RENAME TO landmarks_rtree_v2",
        """CREATE VIRTUAL TABLE landmarks_rtree USING rtree(
            bucket, min_lon, max_lon, min_lat, max_lat, +rid_lo INTEGER, +rid_hi INTEGER)""",
        """INSERT INTO landmarks_rtree (min_lon, max_lon, min_lat, max_lat, rid_lo, rid_hi)
            SELECT lon_deg, lon_deg, lat_deg, lat_deg, rid, rid FROM landmarks""",
        "DROP TABLE landmarks_rtree_v2",
    ),
    (  # 3 -> 4: the same table and rows, CHECKs without IN lists (see the module docstring)
        f"""CREATE TABLE landmarks_v4 (
            rid INTEGER PRIMARY KEY,
            id TEXT NOT NULL,
            name TEXT NOT NULL,
            category TEXT NOT NULL CHECK (category = 'signpost' OR category = 'wall_image'
                                          OR category = 'logo' OR category = 'other'),
            {_PLACE_AND_SIZE}
            status TEXT NOT NULL DEFAULT 'candidate'
                CHECK (status = 'candidate' OR status = 'approved' OR status = 'rejected'),
            status_reason TEXT NOT NULL DEFAULT '',
            distinctiveness REAL, flatness REAL, static REAL, impact REAL,
            points_json TEXT, sightings_json TEXT
        )""",
        f"INSERT INTO landmarks_v4 (rid, {', '.join(COLUMNS)}) "
        f"SELECT rid, {', '.join(COLUMNS)} FROM landmarks",
        "DROP TABLE landmarks",  # foreign keys are off during migrations: no cascade
        "ALTER TABLE landmarks_v4 RENAME TO landmarks",
        _ID_INDEX,
        _NAME_INDEX,
    ),
)
SCHEMA_VERSION = len(MIGRATIONS)

_COLS = ", ".join(f"l.{c}" for c in COLUMNS)
_APP_COLS = ", ".join(f"a.{c}" for c in APPEARANCE_COLUMNS)
_CHUNK = 20_000  # a multiple of BUCKET
_INSERT_ROW = (f"INSERT INTO landmarks (rid, {', '.join(COLUMNS)}) "
               f"VALUES ({', '.join('?' * (len(COLUMNS) + 1))})")
_INSERT_BUCKET = ("INSERT INTO landmarks_rtree (min_lon, max_lon, min_lat, max_lat, rid_lo, "
                  "rid_hi) VALUES (?, ?, ?, ?, ?, ?)")
_INSERT_APPEARANCE = (f"INSERT INTO appearances (rid, {', '.join(APPEARANCE_COLUMNS)}) "
                      f"VALUES ({', '.join('?' * (len(APPEARANCE_COLUMNS) + 1))})")
_RTREE_JOIN = "landmarks_rtree r JOIN landmarks l ON l.rid BETWEEN r.rid_lo AND r.rid_hi"
#: Page cache per connection (KiB): holds the indexes of ~1M landmarks during imports.
CACHE_KIB = 65_536


def _buckets(lat: npt.NDArray[np.float64], lon: npt.NDArray[np.float64], rid0: int
             ) -> list[tuple[Any, ...]]:
    """R*Tree rows (box, rid_lo, rid_hi) for rows ``rid0 ..`` at these positions, in order."""
    n = len(lat)
    pad = (0, -n % BUCKET)  # repeat the last point: boxes unchanged
    lat_b = np.pad(lat, pad, mode="edge").reshape(-1, BUCKET)
    lon_b = np.pad(lon, pad, mode="edge").reshape(-1, BUCKET)
    lo = np.arange(rid0, rid0 + n, BUCKET)
    hi = np.minimum(lo + BUCKET - 1, rid0 + n - 1)
    return list(zip(lon_b.min(axis=1).tolist(), lon_b.max(axis=1).tolist(),
                    lat_b.min(axis=1).tolist(), lat_b.max(axis=1).tolist(),
                    lo.tolist(), hi.tolist(), strict=True))


def _version(conn: sqlite3.Connection) -> int:
    (version,) = conn.execute("PRAGMA user_version").fetchone()
    if version > SCHEMA_VERSION:
        raise InputError(f"landmark database schema version {version} is newer than this "
                         f"program supports ({SCHEMA_VERSION}); upgrade landmark-companion")
    return int(version)


def migrate(conn: sqlite3.Connection, target: int = SCHEMA_VERSION) -> int:
    """Bring the schema to ``target`` in one transaction; return the version before.

    Foreign keys are off meanwhile (SQLite's procedure for rebuilding a table: dropping
    the old one must not cascade) and checked before the commit.
    """
    before = _version(conn)
    if before >= target:
        return before
    (foreign_keys,) = conn.execute("PRAGMA foreign_keys").fetchone()
    conn.execute("PRAGMA foreign_keys = OFF")
    conn.execute("BEGIN IMMEDIATE")
    try:
        version = _version(conn)  # again: another process may have migrated meanwhile
        for step in range(version, target):
            for sql in MIGRATIONS[step]:
                conn.execute(sql)
        if conn.execute("PRAGMA foreign_key_check").fetchone() is not None:
            raise InputError("landmark database: foreign key check failed after migration")
        conn.execute(f"PRAGMA user_version = {int(max(version, target))}")
        conn.execute("COMMIT")
    except BaseException:
        _rollback(conn)
        raise
    finally:
        conn.execute(f"PRAGMA foreign_keys = {int(foreign_keys)}")
    return version


def _rollback(conn: sqlite3.Connection) -> None:
    """Roll back the open transaction, if SQLite has not already done so: after a full disk
    (SQLITE_FULL) or an I/O error it rolls back itself, and a second ROLLBACK would raise
    "no transaction is active" in place of the real cause."""
    if conn.in_transaction:
        conn.execute("ROLLBACK")


class SqliteLandmarkRepository(SqlLandmarkRepository):
    """:class:`~companion.landmarks.repository.LandmarkRepository` over one SQLite file: the
    SQLite dialect of :class:`~companion.landmarks.sql_repo.SqlLandmarkRepository`."""

    MARK = "?"
    TRUE = "1"
    APPEARANCE_KEY = "rid"
    AREA_FROM = _RTREE_JOIN
    ID_CHUNK = 500
    INTEGRITY_ERROR = sqlite3.IntegrityError

    def __init__(self, path: str | Path) -> None:
        self.path = str(path)
        try:
            self._conn = sqlite3.connect(self.path, isolation_level=None)
            self._conn.execute("PRAGMA busy_timeout = 5000")
            self._conn.execute("PRAGMA journal_mode = WAL")
            self._conn.execute("PRAGMA synchronous = NORMAL")
            self._conn.execute("PRAGMA foreign_keys = ON")
            self._conn.execute(f"PRAGMA cache_size = {-CACHE_KIB}")
            migrate(self._conn)
        except sqlite3.OperationalError as err:  # full disk, read-only, no such directory
            raise CompanionError(f"{self.path}: cannot open landmark database ({err})") from None
        except sqlite3.DatabaseError as err:  # not a database, corrupt: the input is bad
            raise InputError(f"{self.path}: cannot open landmark database ({err})") from None

    def schema_version(self) -> int:
        return int(self._conn.execute("PRAGMA user_version").fetchone()[0])

    @contextmanager
    def _transaction(self) -> Iterator[None]:
        self._conn.execute("BEGIN IMMEDIATE")
        try:
            yield
            self._conn.execute("COMMIT")
        except BaseException:
            _rollback(self._conn)
            raise

    def _id_in(self, ids: list[str]) -> tuple[str, Sequence[object]]:
        return f"l.id IN ({','.join('?' * len(ids))})", ids

    def _index_clause(self, box: BBox) -> tuple[str, Sequence[object]]:
        return ("r.min_lon <= ? AND r.max_lon >= ? AND r.min_lat <= ? AND r.max_lat >= ?",
                (box.max_lon_deg, box.min_lon_deg, box.max_lat_deg, box.min_lat_deg))

    def _write(self, batch: LandmarkRows, progress: Progress | None) -> None:
        conn = self._conn
        # never reuse a rid inside an existing bucket's range (that row would be found twice)
        (rid0,) = conn.execute(
            "SELECT max(coalesce((SELECT max(rid) FROM landmarks), 0), "
            "coalesce((SELECT max(rid_hi) FROM landmarks_rtree), 0))").fetchone()
        bulk = self._bulk(batch, BULK_ROWS)
        if bulk:  # inside the transaction: a failure restores the indexes too
            conn.execute("DROP INDEX landmarks_id")
            conn.execute("DROP INDEX landmarks_name")
        self._insert(batch, rid0 + 1, progress)
        if bulk:
            conn.execute(_ID_INDEX)  # fails on a repeated id: rolled back by the caller
            conn.execute(_NAME_INDEX)

    def _insert(self, batch: LandmarkRows, rid0: int, progress: Progress | None) -> None:
        """Rows ``rid0 ..`` in Morton order with their R*Tree buckets, chunk by chunk, then
        the appearance images."""
        lat, lon = batch.positions()
        order = spatial_order(lat, lon)
        rows = batch.rows
        for start in range(0, len(order), _CHUNK):
            part, first = order[start:start + _CHUNK], rid0 + start
            self._conn.executemany(_INSERT_ROW, [(first + k,) + rows[i]
                                                 for k, i in enumerate(part.tolist())])
            self._conn.executemany(_INSERT_BUCKET, _buckets(lat[part], lon[part], first))
            if progress is not None:
                progress(start + len(part))
        if batch.appearances:
            rid = np.empty(len(order), np.int64)
            rid[order] = np.arange(rid0, rid0 + len(order))
            apps = [(int(rid[i]), *app) for i, app in batch.appearances.items()]
            for start in range(0, len(apps), _CHUNK):
                self._conn.executemany(_INSERT_APPEARANCE, apps[start:start + _CHUNK])

    def _delete_ids(self, ids: list[str]) -> None:
        for start in range(0, len(ids), 500):
            part = ids[start:start + 500]
            marks = ",".join("?" * len(part))
            rids = [r[0] for r in self._conn.execute(
                f"SELECT rid FROM landmarks WHERE id IN ({marks})", part)]
            if rids:
                rm = ",".join("?" * len(rids))
                self._conn.execute(f"DELETE FROM landmarks WHERE rid IN ({rm})", rids)
