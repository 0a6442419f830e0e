"""Fixtures for the landmark database tests."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest

from tests.landmarks.helpers import ORIGIN_LAT, ORIGIN_LON, collection, grid_features, write_json
from testsupport.pgcluster import throwaway_cluster


@pytest.fixture()

def sample_map(tmp_path: Path) -> Path:
    """A map of 50 grid landmarks plus one with a data-URI appearance and one with a file."""
    feats = grid_features(50)
    feats[3]["properties"]["appearance"] = "data:image/png;base64,iVBORw0KGgo="
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "a.jpg").write_bytes(b"\xff\xd8jpegbytes")
    feats[4]["properties"]["appearance"] = "img/a.jpg"
    feats[4]["properties"]["appearance_box"] = [1, 2, 3, 4]
    feats[5]["properties"].pop("facing_deg")
    feats[6]["properties"]["scores"] = {"distinctiveness": 0.7, "flatness": 1.0}
    feats[7]["properties"]["points_m"] = [[0, 0, 0], [1, 0, 0], [0, 1, 0.01]]
    feats[8]["properties"]["sightings"] = [[ORIGIN_LON, ORIGIN_LAT, 35.0]]
    feats[9]["properties"]["status"] = "rejected"
    feats[9]["properties"]["status_reason"] = "moved"
    return write_json(tmp_path / "map.geojson", collection(feats))


@pytest.fixture(scope="session")
def postgis_url() -> Iterator[str]:
    """A throwaway PostgreSQL cluster with PostGIS on 127.0.0.1 (skips if not installed)."""
    with throwaway_cluster() as url:
        yield url


@pytest.fixture()
def postgis_db(postgis_url: str) -> Iterator[str]:
    """A fresh, empty database in the throwaway cluster, dropped afterwards."""
    name = f"lm_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(postgis_url, autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name}")
    yield postgis_url.rsplit("/", 1)[0] + "/" + name
    with psycopg.connect(postgis_url, autocommit=True) as conn:
        conn.execute(f"DROP DATABASE {name} WITH (FORCE)")
