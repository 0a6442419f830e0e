"""Admission scores, the impact score, and the name/WGS84/NED table."""

from __future__ import annotations

import dataclasses
import itertools
import math

import cv2
import numpy as np
import pymap3d
import pytest

from companion.core.landmark import Appearance, Landmark, Scores
from companion.errors import InputError
from companion.landmarks.config import AdmissionThresholds, LandmarksConfig
from companion.landmarks.geodesy import LocalFrame, NameTable, corners_ned, facing_normal_ned
from companion.landmarks.scores import (
    distinctiveness_from_vr,
    evaluate,
    flatness_from_points,
    impact_score,
    measure_distinctiveness,
    plane_fit_rms_m,
    static_from_sightings,
    tracker_vr_scorer,
)
from tests.landmarks.helpers import ORIGIN_LAT, ORIGIN_LON

BASE = Landmark("a", "Cafe sign", "signpost", ORIGIN_LAT, ORIGIN_LON, 40.0, 1.0, 0.5, 90.0)


def _png(image: np.ndarray) -> Appearance:
    ok, buf = cv2.imencode(".png", image)
    assert ok
    return Appearance("image/png", buf.tobytes())


def test_distinctiveness_maps_variance_ratio_monotonically_onto_unit_interval() -> None:
    vrs = [0.0, 0.1, 0.5, 1.0, 2.0, 10.0, 1e6]
    ds = [distinctiveness_from_vr(v, 1.0) for v in vrs]
    assert ds[0] == 0.0 and ds[3] == 0.5 and all(0.0 <= d < 1.0 for d in ds)
    assert all(a < b for a, b in itertools.pairwise(ds))
    assert distinctiveness_from_vr(2.0, 2.0) == 0.5


def test_measure_distinctiveness_passes_decoded_image_and_box_to_scorer() -> None:
    image = np.zeros((40, 80, 3), np.uint8)
    image[10:30, 20:60] = (0, 0, 255)
    seen: list[tuple[tuple[int, ...], tuple[int, int, int, int], int]] = []

    def scorer(img: np.ndarray, box: tuple[int, int, int, int]) -> float:
        seen.append((img.shape, box, int(img[15, 30, 2])))
        return 3.0

    app = _png(image)
    assert measure_distinctiveness(app, scorer, vr_half=1.0) == pytest.approx(0.75)
    assert seen[-1] == ((40, 80, 3), (20, 10, 40, 20), 255)  # default: central half
    boxed = dataclasses.replace(app, box_px=(1, 2, 3, 4))
    measure_distinctiveness(boxed, scorer, vr_half=1.0)
    assert seen[-1][1] == (1, 2, 3, 4)
    with pytest.raises(ValueError, match="outside"):
        measure_distinctiveness(dataclasses.replace(app, box_px=(70, 2, 30, 4)), scorer, 1.0)
    with pytest.raises(ValueError, match="cannot decode"):
        measure_distinctiveness(Appearance("image/png", b"nope"), scorer, 1.0)


def test_tracker_scorer_prefers_a_distinct_landmark() -> None:
    scorer = tracker_vr_scorer()
    rng = np.random.default_rng(3)
    noise = rng.integers(0, 256, (60, 60, 3), dtype=np.uint8)
    distinct = noise.copy()
    distinct[15:45, 15:45] = (0, 0, 255)
    d_noise = measure_distinctiveness(_png(noise), scorer, 1.0)
    d_distinct = measure_distinctiveness(_png(distinct), scorer, 1.0)
    assert d_distinct > d_noise
    assert d_distinct > 0.5 > d_noise  # a red plate on noise stands out; noise does not


def test_plane_fit_residual_and_flatness() -> None:
    rng = np.random.default_rng(1)
    uv = rng.uniform(-1, 1, (200, 2))
    basis = np.array([[1.0, 0.0, 0.3], [0.0, 1.0, -0.2]])  # a tilted plane
    on_plane = uv @ basis + np.array([5.0, -3.0, 2.0])
    assert plane_fit_rms_m(on_plane) == pytest.approx(0.0, abs=1e-9)
    assert flatness_from_points(on_plane, 0.05) == pytest.approx(1.0)
    normal = np.cross(basis[0], basis[1])
    normal /= np.linalg.norm(normal)
    # each point twice, 5 cm in front of and behind the plane: the fit stays the plane
    bumpy = np.vstack([on_plane + 0.05 * normal, on_plane - 0.05 * normal])
    assert plane_fit_rms_m(bumpy) == pytest.approx(0.05, rel=1e-6)
    assert flatness_from_points(bumpy, 0.05) == pytest.approx(0.5, rel=1e-5)
    with pytest.raises(ValueError, match="N >= 3"):
        plane_fit_rms_m([[0, 0, 0], [1, 1, 1]])


def _sighting(north_m: float) -> tuple[float, float, float]:
    lat, lon, alt = pymap3d.ned2geodetic(north_m, 0.0, 0.0, BASE.lat_deg, BASE.lon_deg, BASE.alt_m)
    return (float(lon), float(lat), float(alt))


def test_static_counts_consistent_sightings_and_needs_enough_of_them() -> None:
    same = [_sighting(0.3)] * 4
    assert static_from_sightings(BASE, same, 2.0, 3) == 1.0
    half_moved = [_sighting(0.3), _sighting(0.5), _sighting(10.0), _sighting(-8.0)]
    assert static_from_sightings(BASE, half_moved, 2.0, 3) == 0.5
    assert static_from_sightings(BASE, [_sighting(0.0)], 2.0, 3) == pytest.approx(1 / 3)


def test_impact_is_weighted_geometric_mean() -> None:
    assert impact_score([0.8, 0.5, 1.0], [2, 1, 1]) == pytest.approx((0.8**2 * 0.5) ** 0.25)
    assert impact_score([0.0, 1.0, 1.0], [1, 1, 1]) == 0.0
    assert impact_score([0.0, 0.9, 0.9], [0, 1, 1]) == pytest.approx(0.9)
    assert impact_score([1.0, 1.0, 1.0], [1, 2, 3]) == 1.0
    with pytest.raises(ValueError, match="weights"):
        impact_score([1.0, 1.0, 1.0], [0, 0, 0])


def test_evaluate_approves_rejects_or_waits() -> None:
    config = LandmarksConfig(thresholds=AdmissionThresholds(0.3, 0.5, 0.5, 0.4))
    flat = ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (1.0, 1.0, 0.0))
    good = dataclasses.replace(BASE, scores=Scores(distinctiveness=0.9), points_m=flat,
                               sightings=(_sighting(0.1),) * 3)
    up = evaluate(good, config, scorer=None)
    assert up.status == "approved"
    assert (up.scores.flatness, up.scores.static) == (1.0, 1.0)
    assert up.scores.impact == pytest.approx(impact_score([0.9, 1.0, 1.0], [2, 1, 1]))
    bumpy = dataclasses.replace(good, points_m=((0, 0, 0), (1, 0, 0.3), (0, 1, 0.3), (1, 1, 0)))
    up = evaluate(bumpy, config, scorer=None)
    assert up.status == "rejected" and up.status_reason.startswith("flatness 0.")
    unknown = dataclasses.replace(good, sightings=())
    up = evaluate(unknown, config, scorer=None)
    assert (up.status, up.status_reason) == ("candidate", "unknown: static")
    assert up.scores.static is None
    assert up.scores.impact == pytest.approx(impact_score([0.9, 1.0, 0.5], [2, 1, 1]))
    manual = dataclasses.replace(bumpy, status="approved", status_reason="by hand")
    assert evaluate(manual, config, scorer=None).status == "approved"
    assert evaluate(manual, config, scorer=None, restatus=True).status == "rejected"


def test_evaluate_measures_distinctiveness_with_the_scorer() -> None:
    image = np.full((20, 20, 3), 128, np.uint8)
    lm = dataclasses.replace(BASE, appearance=_png(image), scores=Scores(distinctiveness=0.99))
    up = evaluate(lm, LandmarksConfig(vr_half=1.0), scorer=lambda img, box: 0.25)
    assert up.scores.distinctiveness == pytest.approx(0.2)
    assert up.status == "rejected" and "distinctiveness 0.20 < 0.30" in up.status_reason


def test_local_frame_round_trip_and_axes() -> None:
    frame = LocalFrame(ORIGIN_LAT, ORIGIN_LON, 30.0)
    north = frame.to_ned(ORIGIN_LAT + 0.001, ORIGIN_LON, 40.0)
    assert 110.0 < north[0] < 112.0 and abs(north[1]) < 1e-6
    assert north[2] == pytest.approx(-10.0, abs=1e-3)
    east = frame.to_ned(ORIGIN_LAT, ORIGIN_LON + 0.001, 30.0)
    assert 72.0 < east[1] < 75.0 and abs(east[0]) < 0.01
    pts = np.array([[120.0, -35.0, 4.0], [-900.0, 1500.0, -60.0]])
    lat, lon, alt = frame.to_wgs84(pts[:, 0], pts[:, 1], pts[:, 2])
    np.testing.assert_allclose(frame.to_ned(lat, lon, alt), pts, atol=1e-6)
    with pytest.raises(ValueError, match="origin"):
        LocalFrame(91.0, 0.0)


@pytest.mark.parametrize("facing", [None, 0.0, 37.0, 90.0, 200.0, 359.0])
def test_corners_span_the_face_with_outward_normal(facing: float | None) -> None:
    frame = LocalFrame(ORIGIN_LAT, ORIGIN_LON, 30.0)
    lm = dataclasses.replace(BASE, width_m=2.0, height_m=0.5, facing_deg=facing)
    c = corners_ned(lm, frame)
    right, down = c[1] - c[0], c[3] - c[0]
    assert np.linalg.norm(right) == pytest.approx(2.0)
    assert np.linalg.norm(down) == pytest.approx(0.5)
    # seen from the front, right x down points back at the viewer: into the face
    into = np.cross(right, down)
    outward = -into / np.linalg.norm(into)
    np.testing.assert_allclose(outward, facing_normal_ned(facing), atol=1e-9)
    centre = frame.to_ned(lm.lat_deg, lm.lon_deg, lm.alt_m)
    np.testing.assert_allclose(c.mean(axis=0), centre, atol=1e-9)
    if facing is not None:
        assert c[0][2] < c[3][2]  # the top edge is higher (smaller down)
        assert math.isclose(float(np.linalg.norm(facing_normal_ned(facing))), 1.0)


def test_name_table_maps_names_and_ids_to_coordinates() -> None:
    twin1 = dataclasses.replace(BASE, id="t1", name="Bus stop", lat_deg=ORIGIN_LAT + 0.001)
    twin2 = dataclasses.replace(BASE, id="t2", name="Bus stop", lat_deg=ORIGIN_LAT + 0.002)
    frame = LocalFrame(ORIGIN_LAT, ORIGIN_LON, 40.0)
    table = NameTable([BASE, twin1, twin2], frame)
    assert table.lookup("Cafe sign") is BASE and table.lookup("t2") is twin2
    assert table.wgs84("Cafe sign") == (BASE.lat_deg, BASE.lon_deg, BASE.alt_m)
    np.testing.assert_allclose(table.ned("t1"),
                               frame.to_ned(twin1.lat_deg, twin1.lon_deg, twin1.alt_m))
    with pytest.raises(InputError, match="2 landmarks share this name"):
        table.lookup("Bus stop")
    with pytest.raises(InputError, match="no landmark"):
        table.lookup("Nope")
    near, dist = table.nearest(*table.ned("t2") + np.array([1.0, 0.0, 0.0]))
    assert near is twin2 and dist == pytest.approx(1.0, abs=1e-6)
