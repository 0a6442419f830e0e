"""The practical map: spacing, count, busy zones, status, and the reasons given."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from companion.core.landmark import Landmark, Scores
from companion.errors import InputError
from companion.landmarks.config import BusyZone, LandmarksConfig
from companion.landmarks.selection import (
    busy_zones,
    read_busy_zones,
    select_practical_map,
    zones_from_config,
)
from tests.landmarks.helpers import ORIGIN_LAT, ORIGIN_LON


def _at(fid: str, north_m: float, east_m: float, impact: float | None,
        status: str = "approved") -> Landmark:
    lat, lon, _ = pymap3d.ned2geodetic(north_m, east_m, 0.0, ORIGIN_LAT, ORIGIN_LON, 0.0)
    return Landmark(fid, fid, "logo", float(lat), float(lon), 0.0, 1.0, 1.0,
                    status=status, scores=Scores(impact=impact))  # type: ignore[arg-type]


def _reasons(sel: object) -> dict[str, str]:
    return {lo.id: lo.reason for lo in sel.left_out}  # type: ignore[attr-defined]


def test_closer_weaker_landmark_gives_way_to_the_better_one() -> None:
    lms = [_at("a", 0, 0, 0.9), _at("b", 10, 0, 0.8), _at("c", 20, 0, 0.7)]
    sel = select_practical_map(lms, min_spacing_m=15.0, max_count=10)
    assert list(sel.ids) == ["a", "c"]
    assert sel.total_impact == pytest.approx(1.6)
    reason = _reasons(sel)["b"]
    assert reason.startswith("10.0 m from selected 'a'") and "min spacing 15 m" in reason
    sel = select_practical_map(lms, min_spacing_m=5.0, max_count=2)
    assert list(sel.ids) == ["a", "b"]
    assert _reasons(sel)["c"].startswith("max count 2 reached")


def test_random_maps_respect_spacing_count_and_explain_every_candidate() -> None:
    rng = np.random.default_rng(11)
    lms = [_at(f"r{k}", float(n), float(e), float(s)) for k, (n, e, s) in enumerate(
        zip(rng.uniform(-500, 500, 400), rng.uniform(-500, 500, 400),
            rng.uniform(0, 1, 400), strict=True))]
    sel = select_practical_map(lms, min_spacing_m=60.0, max_count=40)
    assert len(sel.ids) == 40
    assert set(sel.ids) | set(_reasons(sel)) == {lm.id for lm in lms}
    assert not set(sel.ids) & set(_reasons(sel))
    by_id = {lm.id: lm for lm in lms}
    chosen = [by_id[i] for i in sel.ids]
    lat = np.array([lm.lat_deg for lm in chosen])
    lon = np.array([lm.lon_deg for lm in chosen])
    n, e, _ = pymap3d.geodetic2ned(lat, lon, 0.0, ORIGIN_LAT, ORIGIN_LON, 0.0)
    d = np.hypot(n[:, None] - n[None, :], e[:, None] - e[None, :])
    assert d[~np.eye(len(lat), dtype=bool)].min() >= 60.0 - 1e-6
    weakest = min(lm.scores.impact or 0.0 for lm in chosen)
    for fid, reason in _reasons(sel).items():
        if reason.startswith("max count"):
            assert (by_id[fid].scores.impact or 0.0) <= weakest


def test_busy_zones_from_config_and_file_exclude_landmarks(tmp_path: Path) -> None:
    lms = [_at("inside", 0, 0, 0.9), _at("hole", 300, 300, 0.9), _at("out", 800, 800, 0.5)]
    dlat, dlon = 0.005, 0.007  # ~550 m x ~510 m
    square = (ORIGIN_LON - dlon, ORIGIN_LAT - dlat, ORIGIN_LON + dlon, ORIGIN_LAT - dlat,
              ORIGIN_LON + dlon, ORIGIN_LAT + dlat, ORIGIN_LON - dlon, ORIGIN_LAT + dlat)
    zones = zones_from_config([BusyZone("market", square)])
    sel = select_practical_map(lms, min_spacing_m=10.0, max_count=10, zones=zones)
    assert _reasons(sel) == {"inside": "inside busy zone 'market'",
                             "hole": "inside busy zone 'market'"}
    ring = [[square[i], square[i + 1]] for i in range(0, 8, 2)]
    lat_h, lon_h, _ = pymap3d.ned2geodetic(300, 300, 0, ORIGIN_LAT, ORIGIN_LON, 0)
    hole = [[lon_h - 0.001, lat_h - 0.001], [lon_h + 0.001, lat_h - 0.001],
            [lon_h + 0.001, lat_h + 0.001], [lon_h - 0.001, lat_h + 0.001]]
    path = tmp_path / "zones.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": "station"},
         "geometry": {"type": "MultiPolygon", "coordinates": [[[*ring, ring[0]], hole]]}}]}))
    config = LandmarksConfig(busy_zones_path=str(path))
    sel = select_practical_map(lms, min_spacing_m=10.0, max_count=10, zones=busy_zones(config))
    assert _reasons(sel) == {"inside": "inside busy zone 'station'"}  # the hole is not busy
    bad = tmp_path / "bad.geojson"
    bad.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [0, 0]}}]}))
    with pytest.raises(InputError, match="feature 0: geometry: expected a Polygon"):
        read_busy_zones(bad)


def test_status_decides_eligibility_and_is_reported() -> None:
    lms = [_at("ok", 0, 0, 0.5), _at("cand", 100, 0, 0.9, "candidate"),
           dataclasses.replace(_at("rej", 200, 0, 0.9, "rejected"), status_reason="moved")]
    sel = select_practical_map(lms, min_spacing_m=10.0, max_count=10)
    assert list(sel.ids) == ["ok"]
    assert _reasons(sel)["rej"] == "status rejected (moved)"
    assert _reasons(sel)["cand"].startswith("status candidate: not admitted yet")
    sel = select_practical_map(lms, min_spacing_m=10.0, max_count=10, include_candidates=True)
    assert list(sel.ids) == ["cand", "ok"]


def test_unscored_landmarks_rank_with_the_unknown_score() -> None:
    lms = [_at("unscored", 0, 0, None), _at("weak", 5, 0, 0.4), _at("strong", 0, 5, 0.6)]
    sel = select_practical_map(lms, min_spacing_m=20.0, max_count=5, unknown_score=0.5)
    assert list(sel.ids) == ["strong"]
    sel = select_practical_map(lms[:2], min_spacing_m=20.0, max_count=5, unknown_score=0.5)
    assert list(sel.ids) == ["unscored"]


def test_reasons_match_a_brute_force_greedy_oracle() -> None:
    rng = np.random.default_rng(23)
    statuses = ["approved"] * 8 + ["candidate", "rejected"]
    lms = [_at(f"o{k:03d}", float(n), float(e), float(s), statuses[int(t)])
           for k, (n, e, s, t) in enumerate(zip(
               rng.uniform(-400, 400, 600), rng.uniform(-400, 400, 600),
               rng.uniform(0, 1, 600), rng.integers(0, 10, 600), strict=True))]
    dlat, dlon = 0.0009, 0.0013  # a ~200 m x ~190 m busy square at the centre
    zone = zones_from_config([BusyZone("plaza", (
        ORIGIN_LON - dlon, ORIGIN_LAT - dlat, ORIGIN_LON + dlon, ORIGIN_LAT - dlat,
        ORIGIN_LON + dlon, ORIGIN_LAT + dlat, ORIGIN_LON - dlon, ORIGIN_LAT + dlat))])
    sel = select_practical_map(lms, min_spacing_m=45.0, max_count=25, zones=zone)
    # oracle: rank, then the rules in order, nearest kept by brute force
    lat0 = np.mean([lm.lat_deg for lm in lms])
    lon0 = np.mean([lm.lon_deg for lm in lms])
    pos = {lm.id: pymap3d.geodetic2ned(lm.lat_deg, lm.lon_deg, 0.0, lat0, lon0, 0.0)[:2]
           for lm in lms}
    inside = zone[0].contains(np.array([lm.lon_deg for lm in lms]),
                              np.array([lm.lat_deg for lm in lms]))
    in_zone = {lm.id for lm, z in zip(lms, inside.tolist(), strict=True) if z}
    kept: list[str] = []
    expected: dict[str, str] = {}
    for lm in sorted(lms, key=lambda x: (-(x.scores.impact or 0.0), x.id)):
        near = [(float(np.hypot(*(np.subtract(pos[lm.id], pos[j])))), j) for j in kept]
        close = min((d, j) for d, j in near if d < 45.0) if any(
            d < 45.0 for d, _ in near) else None
        if lm.status != "approved":
            expected[lm.id] = f"status {lm.status}"
        elif lm.id in in_zone:
            expected[lm.id] = "busy"
        elif close is not None:
            expected[lm.id] = f"near {close[1]}"
        elif len(kept) >= 25:
            expected[lm.id] = "max"
        else:
            kept.append(lm.id)
    assert list(sel.ids) == kept
    got = {}
    for lo in sel.left_out:
        r = lo.reason
        got[lo.id] = ("busy" if r.startswith("inside busy zone") else "max" if r.startswith(
            "max count") else f"near {r.split(chr(39))[1]}" if " m from selected " in r
            else " ".join(r.split(" ")[:2]).rstrip(":"))
    assert got == expected
    assert {v.split(" ")[0] for v in expected.values()} == {"status", "busy", "near", "max"}
