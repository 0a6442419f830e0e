"""``companion landmarks`` as a user runs it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from companion.cli import main
from companion.core.landmark import Scores
from companion.core.map_file import read_map
from companion.landmarks.postgis_repo import PostgisLandmarkRepository
from companion.landmarks.repository import ScoreUpdate, import_map
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository
from tests.landmarks.helpers import ORIGIN_LAT, ORIGIN_LON, collection, grid_features, write_json

ROOT = Path(__file__).resolve().parents[2]
NEAR = f"circle:{ORIGIN_LAT},{ORIGIN_LON},40"


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    status = main(["landmarks", *args])
    out, err = capsys.readouterr()
    return status, out, err


def _approve_all(db: Path) -> None:
    with SqliteLandmarkRepository(db) as repo:
        repo.update_scores(ScoreUpdate(lm.id, Scores(impact=0.5 + int(lm.id[2:]) / 100),
                                       "approved", "test") for lm in repo.iter_all())


def test_bad_map_is_one_line_exit_2_and_database_unchanged(tmp_path: Path,
                                                           sample_map: Path) -> None:
    db = tmp_path / "a.db"
    with SqliteLandmarkRepository(db) as repo:
        import_map(repo, sample_map)
    feats = grid_features(4)
    feats[3]["geometry"]["coordinates"][1] = -95.0
    bad = write_json(tmp_path / "bad.geojson", collection(feats))
    out = subprocess.run([sys.executable, "-m", "companion", "landmarks", "--db", str(db),
                          "import", str(bad)], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, check=False)
    assert out.returncode == 2
    assert out.stderr == (f"{bad}: feature 3: geometry.coordinates[1] (latitude): expected a "
                          "number >= -90 and <= 90, got -95.0\n")
    with SqliteLandmarkRepository(db) as repo:
        assert repo.count() == 50 and repo.get("lm0003") is not None


def test_import_list_show_export(tmp_path: Path, sample_map: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    db = str(tmp_path / "a.db")
    status, out, _ = _run(capsys, "--db", db, "import", str(sample_map))
    assert status == 0 and out.startswith("imported 50 landmarks")
    status, out, _ = _run(capsys, "--db", db, "list", "--json", "--area", NEAR)
    near = json.loads(out)
    assert status == 0 and 0 < len(near) < 50
    assert all(f["type"] == "Feature" for f in near)
    status, out, _ = _run(capsys, "--db", db, "list")
    assert out.splitlines()[-1] == "50 landmarks"
    status, out, _ = _run(capsys, "--db", db, "show", "sign lm0004", "--json",
                          "--origin", f"{ORIGIN_LAT},{ORIGIN_LON},35")
    shown = json.loads(out)
    assert shown["id"] == "lm0004" and shown["appearance"]["box_px"] == [1, 2, 3, 4]
    assert len(shown["ned_m"]["corners"]) == 4 and shown["ned_m"]["centre"][2] == 0.0
    assert _run(capsys, "--db", db, "show", "nope")[0] == 2
    out_map = tmp_path / "exp" / "map.geojson"
    out_map.parent.mkdir()
    status, out, _ = _run(capsys, "--db", db, "export", str(out_map))
    assert status == 0 and sorted(read_map(out_map), key=lambda lm: lm.id) == sorted(
        read_map(sample_map), key=lambda lm: lm.id)


def test_score_then_select_with_reasons(tmp_path: Path, sample_map: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "a.db"
    _run(capsys, "--db", str(db), "import", str(sample_map))
    status, out, _ = _run(capsys, "--db", str(db), "score")
    assert status == 0 and out.startswith("scored 50 landmarks")
    with SqliteLandmarkRepository(db) as repo:
        scored = repo.get("lm0007")  # has flat 3-D points: flatness measured
        assert scored is not None and scored.scores.flatness is not None
        assert scored.scores.impact is not None
    _approve_all(db)
    status, out, _ = _run(capsys, "--db", str(db), "select", "--area", NEAR,
                          "--min-spacing", "12", "--max", "3", "--json")
    sel = json.loads(out)
    assert status == 0 and len(sel["selected"]) == 3
    reasons = {lo["reason"].split(" ")[1] for lo in sel["left_out"]}
    assert {"m", "count"} <= reasons  # spacing and max count both explained
    assert sel["total_impact"] == pytest.approx(
        sum(f["properties"]["scores"]["impact"] for f in sel["selected"]))


def test_sync_from_sqlite_and_postgis(tmp_path: Path, sample_map: Path, postgis_db: str,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    cloud = tmp_path / "cloud.db"
    _run(capsys, "--db", str(cloud), "import", str(sample_map))
    _approve_all(cloud)
    board = tmp_path / "board.db"
    status, out, _ = _run(capsys, "--db", str(board), "sync", "--from", str(cloud),
                          "--area", NEAR, "--min-spacing", "12", "--max", "4")
    assert status == 0 and out.startswith("synced 4 landmarks")
    with SqliteLandmarkRepository(cloud) as src, PostgisLandmarkRepository(postgis_db) as pg:
        pg.import_landmarks(list(src.iter_all()))
    board2 = tmp_path / "board2.db"
    status, out, _ = _run(capsys, "--db", str(board2), "sync", "--from", postgis_db,
                          "--area", NEAR, "--min-spacing", "12", "--max", "4")
    assert status == 0 and out.startswith("synced 4 landmarks")
    with SqliteLandmarkRepository(board) as a, SqliteLandmarkRepository(board2) as b:
        assert list(a.iter_all()) == list(b.iter_all()) and a.count() == 4
