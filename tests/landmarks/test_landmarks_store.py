"""GeoJSON validation, import/export and the SQLite repository."""

from __future__ import annotations

import dataclasses
import gc
import json
import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pymap3d
import pytest

from companion.core.landmark import BBox, Circle, Landmark, Scores, parse_area
from companion.core.map_file import read_map, write_map
from companion.errors import InputError
from companion.landmarks import sqlite_repo
from companion.landmarks.config import LandmarksConfig
from companion.landmarks.repository import ScoreUpdate, import_map
from companion.landmarks.sqlite_repo import MIGRATIONS, SCHEMA_VERSION, SqliteLandmarkRepository
from companion.landmarks.sync import open_onboard
from tests.landmarks.helpers import (
    ORIGIN_LAT,
    ORIGIN_LON,
    collection,
    feature,
    grid_features,
    write_json,
)

REPO_ROOT = Path(__file__).resolve().parents[2]


def _dump(db: Path) -> str:
    conn = sqlite3.connect(db)
    try:
        return "\n".join(conn.iterdump())
    finally:
        conn.close()


def _bad(feats: list[dict[str, Any]], index: int, path: list[str], value: Any) -> list[Any]:
    target = feats[index]
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return feats


@pytest.mark.parametrize(
    ("index", "path", "value", "expected"),
    [
        (2, ["geometry", "coordinates"], [2.35, 91.0, 0.0],
         "feature 2: geometry.coordinates[1] (latitude): expected a number >= -90 and <= 90"),
        (1, ["geometry", "coordinates"], [2.35, 48.0],
         "feature 1: geometry.coordinates: expected [lon, lat, alt_m]"),
        (4, ["properties", "name"], KeyError,
         "feature 4: properties.name: required property is missing"),
        (0, ["properties", "width_m"], KeyError,
         "feature 0: properties.width_m: required property is missing"),
        (3, ["properties", "height_m"], 0,
         "feature 3: properties.height_m: expected a number > 0"),
        (3, ["properties", "category"], "tree",
         'feature 3: properties.category: expected one of signpost, wall_image, logo, other, '
         'got "tree"'),
        (1, ["properties", "facing_deg"], 360,
         "feature 1: properties.facing_deg: expected a number >= 0 and < 360"),
        (2, ["properties", "status"], "maybe", "feature 2: properties.status: expected one of"),
        (2, ["properties", "scores"], {"flatness": 1.5},
         "feature 2: properties.scores.flatness: expected a number >= 0 and <= 1"),
        (1, ["id"], KeyError, "feature 1: id: required"),
        (4, ["id"], "lm0001", "feature 4: id: duplicate id 'lm0001' (already used by feature 1)"),
        (0, ["properties", "appearance"], "missing.png",
         "feature 0: properties.appearance: cannot read"),
        (0, ["properties", "points_m"], [[0, 0]], "feature 0: properties.points_m[0]: expected"),
        (3, ["geometry"], {"type": "LineString", "coordinates": []},
         "feature 3: geometry: expected a Point geometry"),
    ],
)
def test_bad_feature_is_one_line_naming_index_and_field(
    tmp_path: Path, index: int, path: list[str], value: Any, expected: str
) -> None:
    map_path = write_json(tmp_path / "bad.geojson",
                          collection(_bad(grid_features(6), index, path, value)))
    with pytest.raises(InputError) as err:
        read_map(map_path)
    message = str(err.value)
    assert message.startswith(f"{map_path}: ")
    assert expected in message
    assert "\n" not in message


def test_invalid_json_and_non_collection_are_rejected(tmp_path: Path) -> None:
    bad = tmp_path / "broken.geojson"
    bad.write_text('{"type": "FeatureCollection", "features": [')
    with pytest.raises(InputError, match="not valid JSON"):
        read_map(bad)
    with pytest.raises(InputError, match="not a GeoJSON FeatureCollection"):
        read_map(write_json(tmp_path / "f.geojson", feature("a", 1.0, 2.0)))


def test_export_then_import_round_trips_every_field(sample_map: Path, tmp_path: Path) -> None:
    original = read_map(sample_map)
    with SqliteLandmarkRepository(tmp_path / "a.db") as repo:
        import_map(repo, sample_map)
        out = tmp_path / "out" / "exported.geojson"
        out.parent.mkdir()
        assert write_map(out, repo.iter_all()) == len(original)
    assert (out.parent / "exported.appearance").is_dir()
    again = read_map(out)
    assert sorted(again, key=lambda lm: lm.id) == sorted(original, key=lambda lm: lm.id)
    by_id = {lm.id: lm for lm in again}
    assert by_id["lm0004"].appearance is not None
    assert by_id["lm0004"].appearance.data == b"\xff\xd8jpegbytes"
    assert by_id["lm0004"].appearance.box_px == (1, 2, 3, 4)
    assert by_id["lm0005"].facing_deg is None
    embedded = tmp_path / "embedded.geojson"
    write_map(embedded, original, embed_appearance=True)
    assert json.loads(embedded.read_text())["features"][4]["properties"]["appearance"].startswith(
        "data:image/jpeg;base64,")
    assert read_map(embedded) == original


def test_database_uses_wal_foreign_keys_and_current_schema(tmp_path: Path) -> None:
    with SqliteLandmarkRepository(tmp_path / "a.db") as repo:
        assert repo.schema_version() == SCHEMA_VERSION
        conn = repo._conn
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert conn.execute("PRAGMA foreign_keys").fetchone()[0] == 1


def test_old_schema_is_migrated_keeping_rows(tmp_path: Path) -> None:
    db = tmp_path / "old.db"
    conn = sqlite3.connect(db)
    for sql in MIGRATIONS[0]:
        conn.execute(sql)
    conn.execute("PRAGMA user_version = 1")
    conn.execute("INSERT INTO landmarks (rid, id, name, category, lat_deg, lon_deg, alt_m, "
                 "width_m, height_m) VALUES (1, 'old', 'Old sign', 'logo', 10, 20, 5, 1, 1)")
    conn.execute("INSERT INTO landmarks_rtree VALUES (1, 20, 20, 10, 10)")
    conn.commit()
    conn.close()
    with SqliteLandmarkRepository(db) as repo:
        assert repo.schema_version() == SCHEMA_VERSION
        old = repo.get("old")
        assert old is not None and old.name == "Old sign" and old.points_m == ()
        assert [lm.id for lm in repo.query_area(BBox(19.9, 9.9, 20.1, 10.1))] == ["old"]
        assert [lm.id for lm in repo.find_by_name("Old sign")] == ["old"]


def test_schema_3_is_rebuilt_keeping_rows_appearances_and_constraints(tmp_path: Path) -> None:
    db = tmp_path / "v3.db"
    conn = sqlite3.connect(db, isolation_level=None)
    sqlite_repo.migrate(conn, 3)
    conn.execute("INSERT INTO landmarks (rid, id, name, category, lat_deg, lon_deg, alt_m, "
                 "width_m, height_m) VALUES (7, 'old', 'Old sign', 'logo', 10, 20, 5, 1, 1)")
    conn.execute("INSERT INTO appearances (rid, media_type, data) VALUES (7, 'image/png', x'89')")
    conn.execute("INSERT INTO landmarks_rtree (min_lon, max_lon, min_lat, max_lat, rid_lo, "
                 "rid_hi) VALUES (20, 20, 10, 10, 7, 7)")
    conn.close()
    with SqliteLandmarkRepository(db) as repo:  # the table is rebuilt: no cascade meanwhile
        assert repo.schema_version() == SCHEMA_VERSION == 4
        old = repo.get("old")
        assert old is not None and old.appearance is not None and old.appearance.data == b"\x89"
        assert [lm.id for lm in repo.query_area(BBox(19.9, 9.9, 20.1, 10.1))] == ["old"]
        conn = repo._conn
        assert conn.execute("PRAGMA foreign_keys").fetchone()[0] == 1
        (table_sql,) = conn.execute(
            "SELECT sql FROM sqlite_schema WHERE name = 'landmarks'").fetchone()
        assert " IN (" not in table_sql.upper()
        for column, value in (("category", "tree"), ("status", "maybe"), ("width_m", 0)):
            with pytest.raises(sqlite3.IntegrityError, match="CHECK"):
                conn.execute(f"UPDATE landmarks SET {column} = ? WHERE id = 'old'", (value,))
        with pytest.raises(sqlite3.IntegrityError, match="UNIQUE"):
            conn.execute("INSERT INTO landmarks (id, name, category, lat_deg, lon_deg, alt_m, "
                         "width_m, height_m) VALUES ('old', 'x', 'logo', 1, 1, 1, 1, 1)")
        conn.execute("DELETE FROM landmarks WHERE id = 'old'")
        assert conn.execute("SELECT count(*) FROM appearances").fetchone()[0] == 0  # cascade


def test_newer_schema_is_refused(tmp_path: Path) -> None:
    db = tmp_path / "new.db"
    conn = sqlite3.connect(db)
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    conn.close()
    with pytest.raises(InputError, match="newer than this program supports"):
        SqliteLandmarkRepository(db)


def test_duplicate_of_stored_id_fails_and_replace_overwrites(sample_map: Path,
                                                              tmp_path: Path) -> None:
    with SqliteLandmarkRepository(tmp_path / "a.db") as repo:
        import_map(repo, sample_map)
        before = _dump(tmp_path / "a.db")
        newer = write_json(tmp_path / "new.geojson", collection(
            [feature("zz", 1.0, 1.0), feature("lm0003", 2.0, 2.0, name="moved")]))
        with pytest.raises(InputError, match=r"feature 1: id: 'lm0003' already exists"):
            import_map(repo, newer)
        assert _dump(tmp_path / "a.db") == before
        import_map(repo, newer, replace=True)
        moved = repo.get("lm0003")
        assert moved is not None and moved.name == "moved" and moved.appearance is None
        assert repo.count() == 51
        assert repo._conn.execute("SELECT count(*) FROM appearances").fetchone()[0] == 1
        assert [lm.id for lm in repo.query_area(Circle(2.0, 2.0, 10.0))] == ["lm0003"]


@pytest.mark.parametrize("bulk_rows", [10**9, 1000])  # row-by-row indexes, rebuilt indexes
def test_failure_late_in_import_rolls_back_everything(sample_map: Path, tmp_path: Path,
                                                      bulk_rows: int,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sqlite_repo, "BULK_ROWS", bulk_rows)
    db = tmp_path / "a.db"
    with SqliteLandmarkRepository(db) as repo:
        import_map(repo, sample_map)
        before = _dump(db)
        good = Landmark("x0", "x", "logo", 1.0, 1.0, 0.0, 1.0, 1.0)
        records = [dataclasses.replace(good, id=f"x{k}") for k in range(21_000)]
        records[-1] = dataclasses.replace(records[-1], width_m=-1.0)  # CHECK fails in chunk 2
        with pytest.raises(InputError, match="rejected by the database"):
            repo.import_landmarks(records)
        assert _dump(db) == before
        records[-1] = dataclasses.replace(records[-1], width_m=1.0, id="x7")  # repeated id
        with pytest.raises(InputError, match="feature 20999: id: duplicate id 'x7'"):
            repo.import_landmarks(records)
    assert _dump(db) == before
    with SqliteLandmarkRepository(db) as repo:
        assert repo.get("lm0003") is not None and len(repo.find_by_name("sign lm0003")) == 1
        repo.import_landmarks(records[:-1])
        assert repo.count() == 50 + 20_999 and repo.get("x20998") is not None
        conn = repo._conn
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert conn.execute("PRAGMA foreign_key_check").fetchall() == []
        assert conn.execute("SELECT rtreecheck('landmarks_rtree')").fetchone()[0] == "ok"
        assert {r[1] for r in conn.execute("PRAGMA index_list(landmarks)")} == {
            "landmarks_id", "landmarks_name"}


@pytest.mark.parametrize("bulk_rows", ["1000000000", "1000"])
def test_killed_import_leaves_database_exactly_as_it_was(sample_map: Path, tmp_path: Path,
                                                         bulk_rows: str) -> None:
    db = tmp_path / "a.db"
    with SqliteLandmarkRepository(db) as repo:
        import_map(repo, sample_map)
    before = _dump(db)
    big = write_json(tmp_path / "big.geojson", collection(
        [feature(f"b{k}", 10.0 + k * 1e-5, 20.0) for k in range(25_000)]))
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    proc = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("import_worker.py")), str(db), str(big),
         bulk_rows],
        stdout=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("HALFWAY"), line  # rows are written inside the transaction
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert _dump(db) == before
    with SqliteLandmarkRepository(db) as repo:
        assert repo.count() == 50
        assert repo._conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"


def test_area_queries_match_brute_force(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    lat = ORIGIN_LAT + rng.uniform(-0.02, 0.02, 3000)
    lon = ORIGIN_LON + rng.uniform(-0.03, 0.03, 3000)
    records = [Landmark(f"r{k}", "r", "other", float(a), float(o), 0.0, 1.0, 1.0)
               for k, (a, o) in enumerate(zip(lat, lon, strict=True))]
    with SqliteLandmarkRepository(tmp_path / "a.db") as repo:
        repo.import_landmarks(records)
        box = BBox(ORIGIN_LON - 0.01, ORIGIN_LAT - 0.005, ORIGIN_LON + 0.004, ORIGIN_LAT + 0.01)
        got = {lm.id for lm in repo.query_area(box)}
        assert set(repo.area_candidates(box).ids) == got
        want = {f"r{k}" for k in np.flatnonzero(
            (lat >= box.min_lat_deg) & (lat <= box.max_lat_deg)
            & (lon >= box.min_lon_deg) & (lon <= box.max_lon_deg))}
        assert got == want and len(want) > 50
        circle = parse_area(f"circle:{ORIGIN_LAT},{ORIGIN_LON},900")
        got = {lm.id for lm in repo.query_area(circle)}
        assert set(repo.area_candidates(circle).ids) == got
        picked = sorted(got)[:7]
        assert [lm.id for lm in repo.get_many([*picked, "unknown"])] == picked
        n, e, _ = pymap3d.geodetic2ned(lat, lon, 0.0, ORIGIN_LAT, ORIGIN_LON, 0.0)
        want = {f"r{k}" for k in np.flatnonzero(np.hypot(n, e) <= 900.0)}
        assert got == want and len(want) > 50


@pytest.mark.parametrize("text", ["bbox:1,2,3", "circle:1,2,-5", "bbox:3,2,1,4", "disc:1,2,3",
                                  "circle:95,0,10", "bbox:a,b,c,d"])
def test_bad_area_text_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match="expected bbox:"):
        parse_area(text)


def test_replacing_the_newest_rows_never_duplicates_query_results(tmp_path: Path) -> None:
    base = Landmark("x", "x", "logo", ORIGIN_LAT, ORIGIN_LON, 0.0, 1.0, 1.0)
    first = [dataclasses.replace(base, id=f"p{k:02d}", lat_deg=ORIGIN_LAT + k * 1e-4)
             for k in range(20)]
    everything = Circle(ORIGIN_LAT, ORIGIN_LON, 5000.0)
    with SqliteLandmarkRepository(tmp_path / "a.db") as repo:
        repo.import_landmarks(first)
        newest = max(first, key=lambda lm: repo._conn.execute(
            "SELECT rid FROM landmarks WHERE id = ?", (lm.id,)).fetchone()[0])
        moved = dataclasses.replace(newest, lon_deg=ORIGIN_LON + 0.01)  # replaced in place
        repo.import_landmarks([moved], replace=True)
        found = [lm.id for lm in repo.query_area(everything)]
        assert sorted(found) == sorted(lm.id for lm in first)  # each exactly once
        assert repo.area_candidates(everything).ids.count(moved.id) == 1
        assert [lm.lon_deg for lm in repo.query_area(everything) if lm.id == moved.id] == [
            moved.lon_deg]


def test_bulk_load_pauses_and_restores_the_garbage_collector(sample_map: Path,
                                                             tmp_path: Path) -> None:
    bad = tmp_path / "bad.geojson"
    bad.write_text("{")
    assert gc.isenabled()
    with pytest.raises(InputError):
        read_map(bad)
    assert gc.isenabled()
    gc.disable()
    try:
        read_map(sample_map)
        assert not gc.isenabled()  # a caller's choice is kept
    finally:
        gc.enable()


def test_onboard_database_is_seeded_from_the_configured_map_once(sample_map: Path,
                                                                 tmp_path: Path) -> None:
    config = LandmarksConfig(db_path=str(tmp_path / "board.db"), map_path=str(sample_map))
    with open_onboard(config) as repo:
        assert repo.count() == 50
        repo.update_scores([ScoreUpdate("lm0001", Scores(impact=0.9), "approved", "")])
    with open_onboard(config) as repo:  # not empty: the map is not imported again
        assert repo.count() == 50
        first = repo.get("lm0001")
        assert first is not None and first.status == "approved"
    bad = LandmarksConfig(db_path=str(tmp_path / "other.db"), map_path=str(tmp_path / "no"))
    with pytest.raises(InputError, match="cannot read landmark map"):
        open_onboard(bad)
