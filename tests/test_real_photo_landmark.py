"""A user's own landmark: a real photo, not a texture the simulated world generated.

The map gives the landmark's appearance as an image file (here a crop of a real recorded
frame from ../shared/data); the world renders that photo on the facade; the companion must
find it by its reference alone (no training), track it and fix the position from it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.sim.scenario import SCENARIO_DIR
from tests.test_perception import flight
from tracker.pose.types import PoseFix

ROOT = Path(__file__).resolve().parents[1]
OTB = Path(os.environ.get("LMC_SHARED_DATA", ROOT.parent / "shared" / "data")) / "otb"


def test_a_real_photo_landmark_is_found_tracked_and_fixes_the_position(tmp_path: Path) -> None:
    seq = OTB / "boat1" / "img"
    if not seq.is_dir():
        pytest.skip(f"real sequences not available at {OTB} (set LMC_SHARED_DATA)")
    photo = cv2.imread(str(sorted(seq.iterdir())[0]))[200:600, 300:900]  # a real scene
    cv2.imwrite(str(tmp_path / "photo.png"), photo)
    doc = json.loads((ROOT / "config" / "landmarks.geojson").read_text())
    poster = next(f for f in doc["features"] if f["id"] == "wall-01")
    poster["id"] = "harbour-photo"
    poster["properties"].update({"name": "Harbour photo", "appearance": "photo.png"})
    doc["features"] = [poster]
    (tmp_path / "map.geojson").write_text(json.dumps(doc))
    scenario = (SCENARIO_DIR / "survey.toml").read_text()
    scenario = scenario.replace('landmarks = "../landmarks.geojson"',
                                f'landmarks = "{tmp_path / "map.geojson"}"')
    (tmp_path / "photo-survey.toml").write_text(scenario)

    _, _, out = flight(str(tmp_path / "photo-survey.toml"), range(150, 200))
    acquired = [e for r, _, _ in out for e in r.events if e["event"] == "acquired"]
    assert acquired and acquired[0]["landmark"] == "harbour-photo"
    assert acquired[0]["by"] == "features"  # found by its photo, not predicted
    fixes = [(r.fix, st) for r, _, st in out if isinstance(r.fix, PoseFix)]
    assert len(fixes) >= 25
    errors = [np.linalg.norm(np.subtract(f.position_ned_m, st.position_ned_m)) for f, st in fixes]
    assert np.median(errors) < 0.15  # metres, one 3 m x 2 m photo about 12 m away
