"""The city-scale cloud repository: the same interface over PostgreSQL + PostGIS.

``geom`` is a generated ``geometry(Point, 4326)`` column with a GiST index; area queries
use the index (``&&`` with an envelope) and then re-check exact coordinates, like the
SQLite store.  Imports use binary ``COPY`` inside one transaction (all or nothing).  The
schema version lives in ``landmark_schema``; migrations run under an advisory lock.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager
from typing import Any

import psycopg

from companion.core.landmark import BBox, spatial_order
from companion.core.landmark_rows import (
    APPEARANCE_COLUMNS,
    COLUMNS,
    LandmarkRows,
)
from companion.errors import InputError
from companion.landmarks.repository import Progress
from companion.landmarks.sql_repo import SqlLandmarkRepository, first_line

_GEOM_INDEX = "CREATE INDEX landmarks_geom ON landmarks USING gist (geom)"
_NAME_INDEX = "CREATE INDEX landmarks_name ON landmarks (name)"
#: Imports at least this large (and larger than the table) drop the spatial and name
#: indexes and the primary key (with the foreign key that needs it) and build them again
#: afterwards: sorted builds instead of random inserts (the key alone was ~40 % of the
#: server's COPY time); a repeated id fails ``ADD PRIMARY KEY``.
BULK_ROWS = 50_000
_BULK_DROP = (
    "DROP INDEX landmarks_geom",
    "DROP INDEX landmarks_name",
    "ALTER TABLE appearances DROP CONSTRAINT appearances_id_fkey",
    "ALTER TABLE landmarks DROP CONSTRAINT landmarks_pkey",
)
_BULK_REBUILD = (
    "ALTER TABLE landmarks ADD CONSTRAINT landmarks_pkey PRIMARY KEY (id)",
    "ALTER TABLE appearances ADD CONSTRAINT appearances_id_fkey FOREIGN KEY (id) "
    "REFERENCES landmarks (id) ON DELETE CASCADE",
    _GEOM_INDEX,
    _NAME_INDEX,
)

MIGRATIONS: tuple[tuple[str, ...], ...] = (
    (  # 0 -> 1
        "CREATE EXTENSION IF NOT EXISTS postgis",
        """CREATE TABLE landmarks (
            id text PRIMARY KEY,
            name text NOT NULL,
            category text NOT NULL
                CHECK (category IN ('signpost', 'wall_image', 'logo', 'other')),
            lat_deg double precision NOT NULL CHECK (lat_deg BETWEEN -90 AND 90),
            lon_deg double precision NOT NULL CHECK (lon_deg BETWEEN -180 AND 180),
            alt_m double precision NOT NULL,
            width_m double precision NOT NULL CHECK (width_m > 0),
            height_m double precision NOT NULL CHECK (height_m > 0),
            facing_deg double precision CHECK (facing_deg >= 0 AND facing_deg < 360),
            status text NOT NULL DEFAULT 'candidate'
                CHECK (status IN ('candidate', 'approved', 'rejected')),
            status_reason text NOT NULL DEFAULT '',
            distinctiveness double precision, flatness double precision,
            static double precision, impact double precision,
            points_json text, sightings_json text,
            geom geometry(Point, 4326) GENERATED ALWAYS AS
                (ST_SetSRID(ST_MakePoint(lon_deg, lat_deg), 4326)) STORED
        )""",
        _GEOM_INDEX,
        _NAME_INDEX,
        """CREATE TABLE appearances (
            id text PRIMARY KEY REFERENCES landmarks (id) ON DELETE CASCADE,
            media_type text NOT NULL,
            data bytea NOT NULL,
            box_x integer, box_y integer, box_w integer, box_h integer
        )""",
    ),
)
SCHEMA_VERSION = len(MIGRATIONS)
_LOCK_KEY = 0x4C4D4B53  # advisory lock id for migrations ("LMKS")

_COLS = ", ".join(f"l.{c}" for c in COLUMNS)
_APP_COLS = ", ".join(f"a.{c}" for c in APPEARANCE_COLUMNS)
_TEXT_COLUMNS = ("id", "name", "category", "status", "status_reason", "points_json",
                 "sightings_json")
#: Binary COPY: the client sends doubles as 8 bytes instead of formatting them as text
#: (measured: a third of the client's CPU time).
_COPY_TYPES = tuple("text" if c in _TEXT_COLUMNS else "float8" for c in COLUMNS)
_COPY_APPEARANCE_TYPES = ("text", "text", "bytea", "int4", "int4", "int4", "int4")


def redact(url: str) -> str:
    """The URL without its password, for messages."""
    return re.sub(r"(//[^:/@]+):[^@]*@", r"\1:***@", url)


def migrate(conn: psycopg.Connection[Any]) -> int:
    """Bring the schema to ``SCHEMA_VERSION``; return the version before."""
    with conn.transaction():
        conn.execute("SELECT pg_advisory_xact_lock(%s)", (_LOCK_KEY,))
        conn.execute("CREATE TABLE IF NOT EXISTS landmark_schema (version integer NOT NULL)")
        row = conn.execute("SELECT max(version) FROM landmark_schema").fetchone()
        version = int(row[0]) if row and row[0] is not None else 0
        if version > SCHEMA_VERSION:
            raise InputError(f"landmark repository schema version {version} is newer than "
                             f"this program supports ({SCHEMA_VERSION})")
        for step in range(version, SCHEMA_VERSION):
            for sql in MIGRATIONS[step]:
                conn.execute(sql)
        if version < SCHEMA_VERSION:
            conn.execute("DELETE FROM landmark_schema")
            conn.execute("INSERT INTO landmark_schema VALUES (%s)", (SCHEMA_VERSION,))
    return version


class PostgisLandmarkRepository(SqlLandmarkRepository):
    """:class:`~companion.landmarks.repository.LandmarkRepository` over PostGIS: the
    PostgreSQL dialect of :class:`~companion.landmarks.sql_repo.SqlLandmarkRepository`."""

    MARK = "%s"
    TRUE = "true"
    APPEARANCE_KEY = "id"
    AREA_FROM = "landmarks l"
    ID_CHUNK = 5000
    INTEGRITY_ERROR = psycopg.errors.IntegrityError

    def __init__(self, url: str) -> None:
        self.url = url
        try:
            self._conn: psycopg.Connection[Any] = psycopg.connect(url)
        except psycopg.Error as err:
            raise InputError(f"{redact(url)}: cannot connect to the landmark repository "
                             f"({first_line(err)})") from None
        try:
            migrate(self._conn)
        except psycopg.Error as err:
            self._conn.close()
            raise InputError(f"{redact(url)}: cannot prepare the landmark schema "
                             f"({first_line(err)})") from None
        self._conn.autocommit = True

    def schema_version(self) -> int:
        row = self._conn.execute("SELECT max(version) FROM landmark_schema").fetchone()
        return int(row[0]) if row and row[0] is not None else 0

    def _transaction(self) -> AbstractContextManager[object]:
        return self._conn.transaction()

    def _rows(self, sql: str, params: Sequence[object]) -> Iterator[tuple[Any, ...]]:
        with self._conn.cursor(binary=True) as cur:  # binary: half the client's parsing
            cur.execute(sql, params)
            yield from cur

    def _id_in(self, ids: list[str]) -> tuple[str, Sequence[object]]:
        return "l.id = ANY(%s)", (ids,)

    def _index_clause(self, box: BBox) -> tuple[str, Sequence[object]]:
        return ("l.geom && ST_MakeEnvelope(%s, %s, %s, %s, 4326)",
                (box.min_lon_deg, box.min_lat_deg, box.max_lon_deg, box.max_lat_deg))

    def _delete_ids(self, ids: list[str]) -> None:
        self._conn.execute("DELETE FROM landmarks WHERE id = ANY(%s)", (ids,))

    def _write(self, batch: LandmarkRows, progress: Progress | None) -> None:
        bulk = self._bulk(batch, BULK_ROWS)
        for sql in _BULK_DROP if bulk else ():  # DDL is undone on failure
            self._conn.execute(sql)
        self._copy(batch, progress)
        for sql in _BULK_REBUILD if bulk else ():
            self._conn.execute(sql)

    def _copy(self, batch: LandmarkRows, progress: Progress | None) -> None:
        with self._conn.cursor() as cur:
            with cur.copy(f"COPY landmarks ({', '.join(COLUMNS)}) FROM STDIN "
                          "(FORMAT BINARY)") as copy:
                copy.set_types(_COPY_TYPES)
                rows = batch.rows
                for k, i in enumerate(spatial_order(*batch.positions()).tolist(), 1):
                    copy.write_row(rows[i])
                    if progress is not None and k % 20_000 == 0:
                        progress(k)
            if batch.appearances:
                with cur.copy(f"COPY appearances (id, {', '.join(APPEARANCE_COLUMNS)}) "
                              "FROM STDIN (FORMAT BINARY)") as copy:
                    copy.set_types(_COPY_APPEARANCE_TYPES)
                    for i, app in batch.appearances.items():
                        copy.write_row((batch.rows[i][0], *app))
        if progress is not None:
            progress(len(batch))
