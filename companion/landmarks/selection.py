"""The practical map (paper sec. 2.2): for one area, pick landmarks that maximise the total
impact score under a minimum spacing and a maximum count, away from busy zones, and say
why every other candidate was left out.

Picking the heaviest set of points with no two closer than ``min_spacing_m`` is a
maximum-weight independent set in a unit-disk graph (NP-hard); we take the classic greedy
answer: best impact first, keep a landmark if it is far enough from all kept ones, stop at
``max_count``.  Every rejection therefore names the better landmark that displaced it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
import pymap3d

from companion.core.landmark import Candidates, Landmark
from companion.errors import InputError
from companion.landmarks.config import BusyZone, LandmarksConfig


@dataclass(frozen=True)
class ZonePolygon:
    """A busy zone: rings of ``(lon, lat)`` vertices (outer ring, then holes)."""

    name: str
    rings: tuple[npt.NDArray[np.float64], ...]

    def contains(self, lon_deg: npt.NDArray[np.float64], lat_deg: npt.NDArray[np.float64]
                 ) -> npt.NDArray[np.bool_]:
        """Even-odd rule over all rings (so holes are outside)."""
        inside = np.zeros(lon_deg.shape, dtype=bool)
        for ring in self.rings:
            x0, y0 = ring[:, 0], ring[:, 1]
            x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
            for ax, ay, bx, by in zip(x0, y0, x1, y1, strict=True):
                # edge (a, b) crosses the horizontal ray to the right of the point
                crosses = (ay > lat_deg) != (by > lat_deg)
                with np.errstate(divide="ignore", invalid="ignore"):
                    x_cross = ax + (lat_deg - ay) * (bx - ax) / (by - ay)
                inside ^= crosses & (lon_deg < x_cross)
        return inside


#: How each kind of reason reads; ``LeftOut.detail`` holds the values.
REASON_FORMATS = {
    "status": "{0}",
    "busy_zone": "inside busy zone {0!r}",
    "spacing": "{0:.1f} m from selected {1!r} (min spacing {2:g} m; impact {3:.2f} <= {4:.2f})",
    "max_count": "max count {0} reached (impact {1:.2f} ranks lower)",
}


class LeftOut(NamedTuple):
    """A candidate not in the practical map, and why: ``kind`` is a key of
    ``REASON_FORMATS``; the text is formatted only when asked (thousands per query)."""

    id: str
    kind: str
    detail: tuple[object, ...]

    @property
    def reason(self) -> str:
        return REASON_FORMATS[self.kind].format(*self.detail)


@dataclass(frozen=True)
class Selection:
    """The practical map for one area: the chosen ids (best first) and the rest with reasons.

    ``landmarks`` holds the full records of ``ids`` once a repository filled them in
    (:func:`companion.landmarks.sync.select_area`).
    """

    ids: tuple[str, ...]
    impacts: tuple[float, ...]
    left_out: tuple[LeftOut, ...]
    landmarks: tuple[Landmark, ...] = ()

    @property
    def total_impact(self) -> float:
        return float(sum(self.impacts))


def zones_from_config(zones: Sequence[BusyZone]) -> list[ZonePolygon]:
    """Config busy zones (flat lon/lat pairs) as polygons."""
    out = []
    for z in zones:
        ring = np.asarray(z.lon_lat_deg, dtype=np.float64)
        if ring.size % 2 or ring.size < 6:
            raise InputError(f"busy zone {z.name!r}: lon_lat_deg needs >= 3 lon, lat pairs")
        out.append(ZonePolygon(z.name, (ring.reshape(-1, 2),)))
    return out


def read_busy_zones(path: str | Path) -> list[ZonePolygon]:
    """Polygon / MultiPolygon features of a GeoJSON file (name from ``properties.name``)."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
        features = doc["features"] if doc.get("type") == "FeatureCollection" else [doc]
    except (OSError, ValueError, AttributeError, KeyError, TypeError) as err:
        raise InputError(f"{p}: not a readable GeoJSON FeatureCollection ({err})") from None
    out: list[ZonePolygon] = []
    for i, feat in enumerate(features):
        try:
            geom = feat["geometry"]
            polys = {"Polygon": [geom["coordinates"]],
                     "MultiPolygon": geom["coordinates"]}[geom["type"]]
            name = str((feat.get("properties") or {}).get("name", f"zone {i}"))
            for rings in polys:
                arrays = tuple(np.asarray(r, dtype=np.float64)[:, :2] for r in rings)
                if not arrays or any(a.shape[0] < 3 for a in arrays):
                    raise ValueError("a ring has fewer than 3 vertices")
                out.append(ZonePolygon(name, arrays))
        except (KeyError, TypeError, ValueError, IndexError) as err:
            raise InputError(f"{p}: feature {i}: geometry: expected a Polygon or "
                             f"MultiPolygon ({err})") from None
    return out


def busy_zones(config: LandmarksConfig) -> list[ZonePolygon]:
    """All busy zones of the configuration (inline ones, then the file's)."""
    zones = zones_from_config(config.busy_zones)
    if config.busy_zones_path:
        zones += read_busy_zones(config.busy_zones_path)
    return zones


def _eligible(status: str, reason: str, include_candidates: bool) -> str | None:
    """Why a landmark may not be used at all (None: it may)."""
    if status == "rejected":
        return "status rejected" + (f" ({reason})" if reason else "")
    if status == "candidate" and not include_candidates:
        why = f"{reason}; " if reason else ""
        return (f"status candidate: not admitted yet ({why}'companion landmarks score "
                "--restatus' admits it when its scores pass; include_candidates takes it)")
    return None


def select_practical_map(candidates: Candidates | Sequence[Landmark], *, min_spacing_m: float,
                         max_count: int, zones: Sequence[ZonePolygon] = (),
                         include_candidates: bool = False, unknown_score: float = 0.5
                         ) -> Selection:
    """Greedy selection (module docstring) among the landmarks of one area.

    Ranking: impact (``unknown_score`` if not scored) descending, then id.  Distances are
    horizontal, on the local tangent plane at the candidates' mean position.
    """
    c = candidates if isinstance(candidates, Candidates) else Candidates.from_landmarks(
        candidates)
    if not c.ids:
        return Selection((), (), ())
    n_arr, e_arr, _ = pymap3d.geodetic2ned(c.lat_deg, c.lon_deg, 0.0, float(c.lat_deg.mean()),
                                           float(c.lon_deg.mean()), 0.0)
    n_m, e_m = np.asarray(n_arr).tolist(), np.asarray(e_arr).tolist()
    zone_of: list[str | None] = [None] * len(c.ids)
    for z in zones:
        for idx in np.flatnonzero(z.contains(c.lon_deg, c.lat_deg)).tolist():
            zone_of[idx] = zone_of[idx] or z.name
    impact = np.where(np.isnan(c.impact), unknown_score, c.impact).tolist()
    order = sorted(range(len(c.ids)), key=lambda k: (-impact[k], c.ids[k]))
    cell = max(min_spacing_m, 1e-9)
    grid: dict[tuple[int, int], list[int]] = {}
    kept: list[int] = []
    left: list[LeftOut] = []
    for pos, k in enumerate(order):
        if len(kept) >= max_count:  # the map is full: the rest only need their reasons
            left += _rest_reasons(order[pos:], kept, c, n_m, e_m, zone_of, impact,
                                  include_candidates, min_spacing_m, max_count)
            break
        why = _eligible(c.status[k], c.status_reason[k], include_candidates)
        if why is not None:
            left.append(LeftOut(c.ids[k], "status", (why,)))
            continue
        if zone_of[k] is not None:
            left.append(LeftOut(c.ids[k], "busy_zone", (zone_of[k],)))
            continue
        near = _too_close(k, n_m, e_m, grid, cell, min_spacing_m) if min_spacing_m > 0 else None
        if near is not None:
            left.append(_spacing(c.ids[k], near[0], k, near[1], min_spacing_m, c.ids, impact))
            continue
        kept.append(k)
        grid.setdefault((math.floor(n_m[k] / cell), math.floor(e_m[k] / cell)), []).append(k)
    return Selection(tuple(c.ids[k] for k in kept), tuple(impact[k] for k in kept), tuple(left))


def _spacing(lm_id: str, d: float, k: int, j: int, min_spacing_m: float, ids: Sequence[str],
             impact: Sequence[float]) -> LeftOut:
    return LeftOut(lm_id, "spacing", (d, ids[j], min_spacing_m, impact[k], impact[j]))


def _rest_reasons(rest: list[int], kept: list[int], c: Candidates, n_m: list[float],
                  e_m: list[float], zone_of: list[str | None], impact: list[float],
                  include_candidates: bool, min_spacing_m: float, max_count: int
                  ) -> list[LeftOut]:
    """Reasons for the candidates ranked after a full map, the same as the greedy loop
    would give, with the nearest kept landmark found for all of them at once."""
    n, e = np.asarray(n_m), np.asarray(e_m)
    kept_arr = np.asarray(kept)
    out: list[LeftOut] = []
    for start in range(0, len(rest), 1024):  # bounded (block x kept) distance matrices
        block = rest[start:start + 1024]
        idx = np.asarray(block)
        d = np.hypot(n[idx, None] - n[None, kept_arr], e[idx, None] - e[None, kept_arr])
        nearest_arr = d.argmin(axis=1)
        dist = d[np.arange(len(block)), nearest_arr].tolist()
        nearest = nearest_arr.tolist()
        for r, k in enumerate(block):
            why = _eligible(c.status[k], c.status_reason[k], include_candidates)
            if why is not None:
                out.append(LeftOut(c.ids[k], "status", (why,)))
            elif zone_of[k] is not None:
                out.append(LeftOut(c.ids[k], "busy_zone", (zone_of[k],)))
            elif dist[r] < min_spacing_m:
                out.append(_spacing(c.ids[k], dist[r], k, kept[nearest[r]],
                                    min_spacing_m, c.ids, impact))
            else:
                out.append(LeftOut(c.ids[k], "max_count", (max_count, impact[k])))
    return out


def _too_close(k: int, n_m: list[float], e_m: list[float],
               grid: dict[tuple[int, int], list[int]], cell: float, min_spacing_m: float
               ) -> tuple[float, int] | None:
    """(distance, index) of the nearest kept landmark closer than ``min_spacing_m``."""
    ci, cj = math.floor(n_m[k] / cell), math.floor(e_m[k] / cell)
    best: tuple[float, int] | None = None
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            for j in grid.get((ci + di, cj + dj), ()):
                d = math.hypot(n_m[k] - n_m[j], e_m[k] - e_m[j])
                if d < min_spacing_m and (best is None or d < best[0]):
                    best = (d, j)
    return best
