"""The PostGIS repository against a real throwaway PostgreSQL, and sync into SQLite."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import psycopg
import pytest

from companion.core.landmark import BBox, Circle, Landmark, Scores
from companion.core.map_file import read_map
from companion.errors import InputError
from companion.landmarks import postgis_repo
from companion.landmarks.config import LandmarksConfig
from companion.landmarks.postgis_repo import SCHEMA_VERSION, PostgisLandmarkRepository, redact
from companion.landmarks.repository import ScoreUpdate, import_map
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository
from companion.landmarks.sync import sync_practical_map
from tests.landmarks.helpers import ORIGIN_LAT, ORIGIN_LON


def _snapshot(url: str) -> list[tuple[object, ...]]:
    with psycopg.connect(url) as conn:
        rows = conn.execute("SELECT l.*, a.media_type, a.data FROM landmarks l "
                            "LEFT JOIN appearances a USING (id) ORDER BY id").fetchall()
    return [tuple(r) for r in rows]


def test_import_get_and_round_trip_match_sqlite(postgis_db: str, sample_map: Path,
                                                tmp_path: Path) -> None:
    original = sorted(read_map(sample_map), key=lambda lm: lm.id)
    with PostgisLandmarkRepository(postgis_db) as pg, \
            SqliteLandmarkRepository(tmp_path / "a.db") as lite:
        assert pg.schema_version() == SCHEMA_VERSION
        import_map(pg, sample_map)
        import_map(lite, sample_map)
        assert list(pg.iter_all()) == original == list(lite.iter_all())
        assert pg.get("lm0004") == lite.get("lm0004") and pg.get("nope") is None
        assert pg.find_by_name("sign lm0007") == lite.find_by_name("sign lm0007")
        for area in (BBox(ORIGIN_LON, ORIGIN_LAT, ORIGIN_LON + 2.5e-4, ORIGIN_LAT + 3.5e-4),
                     Circle(ORIGIN_LAT + 2e-4, ORIGIN_LON + 2e-4, 25.0)):
            got = pg.query_area(area)
            assert got == lite.query_area(area) and 0 < len(got) < 50
    with PostgisLandmarkRepository(postgis_db) as again:  # reopening does not migrate twice
        assert again.count() == 50


@pytest.mark.parametrize("bulk_rows", [10**9, 100])  # indexes kept, or dropped and rebuilt
def test_bad_import_leaves_repository_unchanged(postgis_db: str, sample_map: Path,
                                                bulk_rows: int,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(postgis_repo, "BULK_ROWS", bulk_rows)
    with PostgisLandmarkRepository(postgis_db) as pg:
        import_map(pg, sample_map)
        before = _snapshot(postgis_db)
        good = Landmark("x0", "x", "logo", 1.0, 1.0, 0.0, 1.0, 1.0)
        records = [dataclasses.replace(good, id=f"x{k}") for k in range(3000)]
        records[-1] = dataclasses.replace(records[-1], height_m=0.0)  # CHECK fails at the end
        with pytest.raises(InputError, match="rejected by the database"):
            pg.import_landmarks(records)
        assert _snapshot(postgis_db) == before
        repeated = [*records[:-1], dataclasses.replace(good, id="x7")]
        with pytest.raises(InputError, match="feature 2999: id: duplicate id 'x7'"):
            pg.import_landmarks(repeated, replace=True)  # bulk: fails ADD PRIMARY KEY
        assert _snapshot(postgis_db) == before
        with pytest.raises(InputError, match=r"feature 1: id: 'lm0002' already exists"):
            pg.import_landmarks([dataclasses.replace(good, id="new"),
                                 dataclasses.replace(good, id="lm0002")])
        assert _snapshot(postgis_db) == before
        pg.import_landmarks([dataclasses.replace(good, id="lm0003")], replace=True)
        replaced = pg.get("lm0003")
        assert replaced is not None and replaced.appearance is None and pg.count() == 50
        pg.import_landmarks(records[:-1])  # the good ones, through the same path
        assert pg.count() == 50 + 2999
        assert len(pg.query_area(Circle(1.0, 1.0, 1.0))) == 3000  # 2999 + replaced lm0003
        indexes = {r[0] for r in pg._conn.execute(
            "SELECT indexname FROM pg_indexes WHERE tablename = 'landmarks'")}
        assert {"landmarks_geom", "landmarks_name", "landmarks_pkey"} <= indexes
        constraints = {r[0] for r in pg._conn.execute(
            "SELECT conname FROM pg_constraint WHERE contype IN ('p', 'f')")}
        assert {"landmarks_pkey", "appearances_id_fkey"} <= constraints
        pg._conn.execute("DELETE FROM landmarks WHERE id = 'lm0004'")  # had an appearance
        assert pg._conn.execute("SELECT count(*) FROM appearances").fetchone()[0] == 0


def test_update_scores(postgis_db: str, sample_map: Path) -> None:
    with PostgisLandmarkRepository(postgis_db) as pg:
        import_map(pg, sample_map)
        pg.update_scores([ScoreUpdate("lm0001", Scores(0.9, 1.0, 0.8, 0.88), "approved", "ok")])
        lm = pg.get("lm0001")
        assert lm is not None and lm.scores == Scores(0.9, 1.0, 0.8, 0.88)
        assert (lm.status, lm.status_reason) == ("approved", "ok")


def test_sync_pulls_the_practical_map_into_sqlite(postgis_db: str, tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    records = [Landmark(f"c{k}", f"c{k}", "wall_image", ORIGIN_LAT + float(a),
                        ORIGIN_LON + float(o), 30.0, 2.0, 1.0, status="approved",
                        scores=Scores(impact=float(s)))
               for k, (a, o, s) in enumerate(zip(rng.uniform(-0.01, 0.01, 500),
                                                 rng.uniform(-0.01, 0.01, 500),
                                                 rng.uniform(0, 1, 500), strict=True))]
    area = Circle(ORIGIN_LAT, ORIGIN_LON, 600.0)
    config = LandmarksConfig(min_spacing_m=80.0, max_count=12)
    with PostgisLandmarkRepository(postgis_db) as pg, \
            SqliteLandmarkRepository(tmp_path / "board.db") as board:
        pg.import_landmarks(records)
        board.import_landmarks([dataclasses.replace(records[0], id="local-only")])
        sel = sync_practical_map(pg, board, area, config, ())
        assert len(sel.ids) == 12
        stored = {lm.id: lm for lm in board.iter_all()}
        assert set(stored) == set(sel.ids) | {"local-only"}
        for lm_id in sel.ids:
            assert stored[lm_id] == pg.get(lm_id)
        in_area = pg.query_area(area)
        assert len(sel.ids) + len(sel.left_out) == len(in_area)
        candidates = pg.area_candidates(area)
        assert sorted(candidates.ids) == [lm.id for lm in in_area]
        by_id = {lm.id: lm for lm in in_area}
        for k, lm_id in enumerate(candidates.ids):
            assert candidates.impact[k] == by_id[lm_id].scores.impact
            assert candidates.lat_deg[k] == by_id[lm_id].lat_deg


def test_unreachable_repository_is_one_line_without_password() -> None:
    url = "postgresql://user:secret@127.0.0.1:1/none?connect_timeout=2"
    with pytest.raises(InputError) as err:
        PostgisLandmarkRepository(url)
    assert "secret" not in str(err.value) and "\n" not in str(err.value)
    assert redact(url).startswith("postgresql://user:***@127.0.0.1:1/")
