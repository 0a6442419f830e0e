"""Fixtures for the landmark database tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.landmarks.helpers import ORIGIN_LAT, ORIGIN_LON, collection, grid_features, write_json


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
