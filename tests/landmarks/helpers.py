"""Helpers for the landmark database tests: small maps built in code."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

ORIGIN_LAT, ORIGIN_LON = 48.8566, 2.3522


def feature(fid: str, lat: float, lon: float, **props: Any) -> dict[str, Any]:
    """A valid landmark feature; keyword arguments override or add properties."""
    base: dict[str, Any] = {
        "name": f"sign {fid}", "category": "signpost", "width_m": 1.2, "height_m": 0.8,
        "facing_deg": 90.0,
    }
    base.update(props)
    return {
        "type": "Feature", "id": fid,
        "geometry": {"type": "Point", "coordinates": [lon, lat, 35.0]},
        "properties": base,
    }


def collection(features: list[dict[str, Any]]) -> dict[str, Any]:
    return {"type": "FeatureCollection", "features": copy.deepcopy(features)}


def grid_features(n: int, step_deg: float = 1e-4) -> list[dict[str, Any]]:
    """n features on a square grid around the origin, ids lm0000..."""
    side = int(n**0.5) + 1
    return [
        feature(f"lm{k:04d}", ORIGIN_LAT + (k // side) * step_deg,
                ORIGIN_LON + (k % side) * step_deg)
        for k in range(n)
    ]


def write_json(path: Path, doc: object) -> Path:
    path.write_text(json.dumps(doc))
    return path
