"""The landmarks of one flight: where they come from and which of them can be acquired.

``companion run`` flies one of two maps (docs/landmarks.md, "The flight's map"):

* ``landmarks.map_path`` set: that GeoJSON file, every landmark not ``rejected`` (the
  explicit alternative; the database is not read);
* ``landmarks.map_path = ""``: the **practical map** selected from the database
  ``landmarks.db_path`` (:func:`companion.landmarks.sync.select_area`) in
  ``landmarks.area``, or within ``landmarks.area_radius_m`` of the EKF origin.

Either way every landmark is placed in local NED about the EKF origin
(``mavlink.origin_*``).  Heights: a landmark's ``alt_m`` and the origin's ``origin_alt_m``
are both metres above mean sea level (AMSL, the datum of the autopilot's EKF origin), so
their difference is the landmark's height above the origin; docs/decisions.md says why
no geoid model is needed for that.

:func:`acquisition_report` says, for every landmark of the map, whether the acquisition
can find it and, if not, why; :func:`static_blocker` names the reason no fix can come at
all when it is already known at start (no landmark, none with a usable reference, an
origin far from every landmark).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from companion.core.landmark import BBox, Circle, Landmark, parse_area
from companion.core.map_file import read_map
from companion.errors import ConfigError, InputError
from companion.landmarks.geodesy import LocalFrame
from companion.landmarks.selection import busy_zones
from companion.landmarks.sqlite_repo import SqliteLandmarkRepository
from companion.landmarks.sync import select_area
from companion.pipeline.health import Blocker
from companion.settings import Settings
from tracker.acquire import MIN_REFERENCE_SIDE_PX
from tracker.pose.types import MapLandmark

log = logging.getLogger(__name__)

ImageU8 = npt.NDArray[np.uint8]
#: The mean Earth radius (m), for the great-circle distance of :func:`ground_distance_m`.
EARTH_RADIUS_M = 6_371_008.8
#: How many left-out landmarks the log lists one by one (the rest are counted).
LIST_AT_MOST = 20


@dataclass(frozen=True)
class PracticalMap:
    """The landmarks of this flight in local NED, and the images to look for.

    ``unusable``: landmark id -> why it cannot be acquired (no or an unreadable
    appearance image); ``left_out``: (id, reason) of the database's landmarks the
    selection did not take; ``nearest_m``: ground distance from the origin to the nearest
    landmark (of the map, or of the whole database when nothing was selected).
    """

    landmarks: tuple[MapLandmark, ...]
    references: dict[str, ImageU8]
    origin: LocalFrame
    unusable: Mapping[str, str] = field(default_factory=dict)
    left_out: tuple[tuple[str, str], ...] = ()
    described: str = "the given landmarks"
    nearest_m: float | None = None
    nearest_id: str | None = None


def ground_distance_m(lat0_deg: float, lon0_deg: float, lat_deg: npt.ArrayLike,
                      lon_deg: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Great-circle distances (haversine, m) from one point to many."""
    p0, l0 = math.radians(lat0_deg), math.radians(lon0_deg)
    p = np.radians(np.asarray(lat_deg, np.float64))
    dl = np.radians(np.asarray(lon_deg, np.float64)) - l0
    a = np.sin((p - p0) / 2) ** 2 + math.cos(p0) * np.cos(p) * np.sin(dl / 2) ** 2
    return np.asarray(2 * EARTH_RADIUS_M * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0))))


def reference_image(lm: Landmark) -> tuple[ImageU8 | None, str | None]:
    """(the appearance reference cropped to its box, None) or (None, why there is none)."""
    if lm.appearance is None:
        return None, "no appearance image: nothing to look for (add one to the map)"
    image = cv2.imdecode(np.frombuffer(lm.appearance.data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        return None, f"appearance image unreadable ({lm.appearance.media_type}, " \
                     f"{len(lm.appearance.data)} bytes)"
    if lm.appearance.box_px is not None:
        x, y, w, h = lm.appearance.box_px
        image = image[max(y, 0):y + h, max(x, 0):x + w]
        if image.size == 0:
            return None, f"appearance_box {list(lm.appearance.box_px)} lies outside the image"
    return np.asarray(image, np.uint8), None


def _origin(settings: Settings) -> LocalFrame:
    mav = settings.mavlink
    if mav.origin_lat_deg == 0.0 and mav.origin_lon_deg == 0.0:
        raise ConfigError("mavlink.origin_lat_deg, mavlink.origin_lon_deg: expected the EKF "
                          "origin (WGS84) that the landmark map is placed about, got 0, 0")
    return LocalFrame(mav.origin_lat_deg, mav.origin_lon_deg, mav.origin_alt_m)


def _from_file(path: str) -> list[Landmark]:
    if not Path(path).is_file():
        raise InputError(f"{path}: landmarks.map_path: no such file (set it to a GeoJSON map, "
                         "or to \"\" to fly the practical map of the landmark database)")
    return [lm for lm in read_map(path) if lm.status != "rejected"]


def flight_area(settings: Settings) -> BBox | Circle:
    """``landmarks.area``, or the circle of ``area_radius_m`` about the EKF origin."""
    cfg = settings.landmarks
    if cfg.area:
        try:
            return parse_area(cfg.area)
        except ValueError as err:
            raise ConfigError(f"landmarks.area: {err}") from None
    mav = settings.mavlink
    return Circle(mav.origin_lat_deg, mav.origin_lon_deg, cfg.area_radius_m)


def _from_database(settings: Settings, area: BBox | Circle
                   ) -> tuple[list[Landmark], tuple[tuple[str, str], ...], str]:
    cfg = settings.landmarks
    if not Path(cfg.db_path).is_file():
        raise InputError(f"{cfg.db_path}: landmarks.db_path: no such database (import "
                         "landmarks with `companion landmarks import`, or set "
                         "landmarks.map_path to a GeoJSON map)")
    with SqliteLandmarkRepository(cfg.db_path) as repo:
        selection = select_area(repo, area, cfg, busy_zones(cfg))
        total = repo.count()
    left = tuple((lo.id, lo.reason) for lo in selection.left_out)
    where = cfg.area or f"within {cfg.area_radius_m:g} m of the EKF origin"
    return list(selection.landmarks), left, \
        f"the practical map of {cfg.db_path} ({total} landmarks) {where}"


def _nearest(settings: Settings, records: list[Landmark]) -> tuple[float | None, str | None]:
    """The nearest landmark to the origin: of ``records``, else of the whole database."""
    mav = settings.mavlink
    if records:
        ids = [lm.id for lm in records]
        lat = [lm.lat_deg for lm in records]
        lon = [lm.lon_deg for lm in records]
    elif not settings.landmarks.map_path and Path(settings.landmarks.db_path).is_file():
        with SqliteLandmarkRepository(settings.landmarks.db_path) as repo:
            c = repo.area_candidates(BBox(-180.0, -90.0, 180.0, 90.0))
        ids, lat, lon = list(c.ids), list(c.lat_deg), list(c.lon_deg)
    else:
        return None, None
    if not ids:
        return None, None
    d = ground_distance_m(mav.origin_lat_deg, mav.origin_lon_deg, lat, lon)
    k = int(np.argmin(d))
    return float(d[k]), ids[k]


def placed(frame: LocalFrame, records: Iterable[Landmark]
           ) -> tuple[list[MapLandmark], dict[str, ImageU8], dict[str, str]]:
    """Landmark records in NED about ``frame``, their appearance references, and why each
    landmark without a usable reference has none."""
    landmarks, references, unusable = [], {}, {}
    for lm in records:
        n, e, d = (float(v) for v in frame.to_ned(lm.lat_deg, lm.lon_deg, lm.alt_m))
        landmarks.append(MapLandmark(lm.id, (n, e, d), lm.width_m, lm.height_m,
                                     lm.facing_deg, lm.category))
        image, why = reference_image(lm)
        if image is not None:
            references[lm.id] = image
        else:
            unusable[lm.id] = str(why)
    return landmarks, references, unusable


def load_practical_map(settings: Settings) -> PracticalMap:
    """The flight's map (module docstring) placed about the configured EKF origin."""
    frame = _origin(settings)
    path = settings.landmarks.map_path
    left: tuple[tuple[str, str], ...] = ()
    if path:
        records, described = _from_file(path), f"the map file {path}"
    else:
        records, left, described = _from_database(settings, flight_area(settings))
    landmarks, references, unusable = placed(frame, records)
    nearest_m, nearest_id = _nearest(settings, records)
    return PracticalMap(tuple(landmarks), references, frame, unusable, left, described,
                        nearest_m, nearest_id)


def acquisition_report(pmap: PracticalMap, perception: Any) -> dict[str, Any]:
    """Which landmarks were loaded, which have a reference the acquisition can use, and
    why each of the others cannot be acquired (for the log, the status and an event).

    ``perception`` is a :class:`companion.perception.Perception` (its matcher holds the
    prepared references; ``unmatchable`` the images it refused, e.g. blank ones)."""
    refs = perception.matcher.references
    cannot = {**pmap.unusable, **perception.unmatchable}
    weak = {lid: _weak(r) for lid, r in refs.items() if not r.matchable and lid not in cannot}
    return {
        "from": pmap.described,
        "loaded": [lm.landmark_id for lm in pmap.landmarks],
        "with_reference": sorted(lid for lid in refs if lid not in cannot),
        "cannot_acquire": dict(sorted(cannot.items())),
        "weak": weak,
        "left_out": dict(pmap.left_out[:LIST_AT_MOST]),
        "left_out_count": len(pmap.left_out),
        "nearest_landmark_m": None if pmap.nearest_m is None else round(pmap.nearest_m, 1),
    }


def _weak(ref: Any) -> str:
    """Why a usable reference is found only by colour search or from a fix."""
    w, h = ref.size_px
    why = f"too small ({w}x{h} px, under {MIN_REFERENCE_SIDE_PX} px a side)" \
        if min(w, h) < MIN_REFERENCE_SIDE_PX else f"few features ({len(ref.keypoints_px)})"
    return f"{why}: found by colour search or from a fix only, not by feature matching"


def log_report(report: Mapping[str, Any]) -> None:
    """The report as log lines: one summary, one WARNING per landmark that cannot be
    acquired, one INFO per landmark the selection left out (at most ``LIST_AT_MOST``)."""
    log.info("flying with %d landmarks from %s; %d with a usable reference image (%s)",
             len(report["loaded"]), report["from"], len(report["with_reference"]),
             ", ".join(report["with_reference"]) or "none")
    for lid, why in report["cannot_acquire"].items():
        log.warning("landmark %s cannot be acquired: %s", lid, why)
    for lid, why in report["weak"].items():
        log.info("landmark %s: %s", lid, why)
    for lid, why in report["left_out"].items():
        log.info("landmark %s not in the practical map: %s", lid, why)
    more = report["left_out_count"] - len(report["left_out"])
    if more > 0:
        log.info("... and %d more landmarks not in the practical map", more)


def static_blocker(pmap: PracticalMap, report: Mapping[str, Any], max_origin_distance_m: float
                   ) -> Blocker | None:
    """Why no fix can come, when that is already known before the first frame."""
    if pmap.nearest_m is not None and pmap.nearest_m > max_origin_distance_m:
        return Blocker("origin-far", f"the EKF origin is {pmap.nearest_m / 1000:.1f} km from "
                       f"the nearest landmark {pmap.nearest_id!r} (landmarks."
                       f"max_origin_distance_m = {max_origin_distance_m:g}): check "
                       "mavlink.origin_lat_deg/origin_lon_deg and the map")
    if not pmap.landmarks:
        left = report["left_out_count"]
        return Blocker("no-landmarks", f"{pmap.described} holds no landmark to fly"
                       + (f" ({left} left out: see the log)" if left else ""))
    if not report["with_reference"]:
        return Blocker("no-references", f"none of the {len(pmap.landmarks)} landmarks has a "
                       "usable appearance image: see the log for each one's reason")
    return None
