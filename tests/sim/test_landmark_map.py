"""Reading the GeoJSON landmark map into the simulated world."""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pymap3d
import pytest

from companion.core.stream_format import Origin
from companion.errors import InputError
from companion.sim.world import World, load_landmark_map

ORIGIN = Origin(47.0, 8.0, 400.0)


def feature(fid: Any = "a", **props: Any) -> dict[str, Any]:
    lat, lon, alt = pymap3d.ned2geodetic(10.0, 5.0, -3.0, ORIGIN.lat, ORIGIN.lon, ORIGIN.alt_m)
    base = {"name": "A", "category": "wall_image", "width_m": 2.0, "height_m": 1.0,
            "facing_deg": 180.0}
    return {"type": "Feature", "id": fid, "geometry": {"type": "Point",
            "coordinates": [lon, lat, alt]}, "properties": {**base, **props}}


def write_map(path: Path, *features: dict[str, Any]) -> Path:
    path.write_text(json.dumps({"type": "FeatureCollection", "features": list(features)}))
    return path


def test_position_facing_and_corners(tmp_path: Path) -> None:
    (lm,) = load_landmark_map(write_map(tmp_path / "m.geojson", feature()), ORIGIN)
    assert np.allclose(lm.centre_ned, [10.0, 5.0, -3.0], atol=1e-6)
    c = lm.quad.corners_ned
    # facing south: a viewer looks north, so the face's right edge is to the east
    assert c[1, 1] - c[0, 1] == pytest.approx(2.0) and c[3, 2] - c[0, 2] == pytest.approx(1.0)
    assert np.allclose(lm.quad.normal_ned, [-1.0, 0.0, 0.0])


def test_appearance_file_and_data_uri(tmp_path: Path) -> None:
    img = np.random.default_rng(0).integers(0, 256, (20, 32, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "ref.png"), img)
    uri = "data:image/png;base64," + base64.b64encode(cv2.imencode(".png", img)[1]).decode()
    boxed = feature("f", appearance="ref.png", appearance_box=[2, 3, 10, 8])
    central = feature("u", appearance=uri)  # no box: the face is the central half
    f, u = load_landmark_map(write_map(tmp_path / "m.geojson", boxed, central), ORIGIN)
    assert np.array_equal(f.quad.texture, img[3:11, 2:12])
    assert np.array_equal(u.quad.texture, img[5:15, 8:24])


def test_generated_textures_are_deterministic_per_seed_and_id(tmp_path: Path) -> None:
    path = write_map(tmp_path / "m.geojson", feature("a"), feature("b", category="signpost"))
    a1, b1 = load_landmark_map(path, ORIGIN, seed=1)
    a2, _ = load_landmark_map(path, ORIGIN, seed=1)
    a3, _ = load_landmark_map(path, ORIGIN, seed=2)
    assert np.array_equal(a1.quad.texture, a2.quad.texture)
    assert not np.array_equal(a1.quad.texture, a3.quad.texture)
    assert not np.array_equal(a1.quad.texture[:10, :10], b1.quad.texture[:10, :10])


def test_world_adds_a_facade_per_plane_and_poles(tmp_path: Path) -> None:
    # same plane (facing south, north = 10 m), 10 m further east
    lat, lon, alt = pymap3d.ned2geodetic(10.0, 15.0, -3.0, ORIGIN.lat, ORIGIN.lon, ORIGIN.alt_m)
    second = feature("b")
    second["geometry"]["coordinates"] = [lon, lat, alt]
    sign = feature("s", category="signpost")
    world = World(load_landmark_map(write_map(tmp_path / "m.geojson", feature("a"), second,
                                              sign), ORIGIN))
    assert len(world.facades) == 1 and len(world.poles) == 1
    facade = world.facades[0].corners_ned
    assert facade[:, 1].min() < 5.0 - 1.0 and facade[:, 1].max() > 15.0 + 1.0
    assert np.allclose(facade[:, 0], 10.0 + 0.02)  # just behind the images
    assert facade[:, 2].max() == pytest.approx(0.0)  # reaches the ground


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda f: f.pop("id"), "id: required"),
        (lambda f: f["properties"].update(category="tree"), "category: expected one of"),
        (lambda f: f["properties"].update(width_m="big"), "width_m: expected a number"),
        (lambda f: f["properties"].update(height_m=0), "height_m: expected a number > 0"),
        (lambda f: f["geometry"].update(type="Polygon"), "expected a Point geometry"),
        (lambda f: f["properties"].update(appearance="nope.png"), "cannot read"),
        (lambda f: f["properties"].update(appearance="data:image/png;base64,aGk="),
         "appearance is not a readable image"),
    ],
)
def test_bad_map_is_one_line_error(tmp_path: Path, mutate: Any, message: str) -> None:
    f = feature()
    mutate(f)
    with pytest.raises(InputError, match=message) as info:
        load_landmark_map(write_map(tmp_path / "m.geojson", f), ORIGIN)
    assert "m.geojson" in str(info.value) and "\n" not in str(info.value)


def test_missing_or_invalid_map(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="landmark map is missing"):
        load_landmark_map(tmp_path / "none.geojson", ORIGIN)
    (tmp_path / "x.geojson").write_text("{")
    with pytest.raises(InputError, match="not valid JSON"):
        load_landmark_map(tmp_path / "x.geojson", ORIGIN)
    with pytest.raises(InputError, match="duplicate id"):
        load_landmark_map(write_map(tmp_path / "d.geojson", feature("a"), feature("a")), ORIGIN)
