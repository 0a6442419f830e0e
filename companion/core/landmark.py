"""The landmark record (DESIGN.md, Contracts) and the area types used to query landmarks.

A :class:`Landmark` is a frozen value: id, name, category, WGS84 position, facing,
physical size, appearance (the reference image, kept inside the database), admission
scores and status with its reason.  Optional ``points_m`` (3-D points measured on the
landmark's face, e.g. by a laser, in metres in any Cartesian frame) and ``sightings``
(positions at which the landmark was observed, WGS84 ``(lon, lat, alt_m)``) feed the
flatness and static scores (:mod:`companion.landmarks.scores`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
import numpy.typing as npt
import pymap3d

Category = Literal["signpost", "wall_image", "logo", "other"]
Status = Literal["candidate", "approved", "rejected"]
CATEGORIES: tuple[str, ...] = get_args(Category)
STATUSES: tuple[str, ...] = get_args(Status)

Point3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Scores:
    """Admission scores, each in [0, 1] or ``None`` when not known (yet).

    ``impact`` is the combined landmark impact score (docs/landmarks.md).
    """

    distinctiveness: float | None = None
    flatness: float | None = None
    static: float | None = None
    impact: float | None = None


@dataclass(frozen=True, slots=True)
class Appearance:
    """The landmark's reference image (encoded bytes, e.g. PNG or JPEG).

    ``box_px`` is ``(x, y, w, h)`` of the landmark inside the image (top-left corner,
    pixels); ``None`` means the landmark fills the central half of the image and the
    rest is its surroundings.
    """

    media_type: str
    data: bytes
    box_px: tuple[int, int, int, int] | None = None


@dataclass(frozen=True, slots=True)
class Landmark:
    """One landmark. Angles in degrees, sizes in metres; ``facing_deg`` is the azimuth
    of the face's outward normal from north (``None``: lying flat, facing up)."""

    id: str
    name: str
    category: Category
    lat_deg: float
    lon_deg: float
    alt_m: float
    width_m: float
    height_m: float
    facing_deg: float | None = None
    status: Status = "candidate"
    status_reason: str = ""
    scores: Scores = Scores()
    appearance: Appearance | None = None
    points_m: tuple[Point3, ...] = ()
    sightings: tuple[Point3, ...] = ()


@dataclass(frozen=True, slots=True)
class BBox:
    """A WGS84 box in degrees (west <= east; boxes crossing 180 deg are not supported)."""

    min_lon_deg: float
    min_lat_deg: float
    max_lon_deg: float
    max_lat_deg: float

    def bbox(self) -> BBox:
        return self

    def contains(self, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        lat = np.asarray(lat_deg, dtype=np.float64)
        lon = np.asarray(lon_deg, dtype=np.float64)
        return (
            (lat >= self.min_lat_deg)
            & (lat <= self.max_lat_deg)
            & (lon >= self.min_lon_deg)
            & (lon <= self.max_lon_deg)
        )

    def centre(self) -> tuple[float, float]:
        """(lat, lon) of the middle of the box."""
        return (
            (self.min_lat_deg + self.max_lat_deg) / 2.0,
            (self.min_lon_deg + self.max_lon_deg) / 2.0,
        )


@dataclass(frozen=True, slots=True)
class Circle:
    """All points within ``radius_m`` (ellipsoidal ground distance) of a centre."""

    lat_deg: float
    lon_deg: float
    radius_m: float

    def bbox(self) -> BBox:
        """A box that certainly contains the circle (a small margin is added)."""
        dlat = math.degrees(self.radius_m / 6_356_752.0) * 1.001
        coslat = max(math.cos(math.radians(min(abs(self.lat_deg) + dlat, 90.0))), 1e-9)
        dlon = min(math.degrees(self.radius_m / (6_378_137.0 * coslat)) * 1.001, 180.0)
        return BBox(
            self.lon_deg - dlon,
            max(self.lat_deg - dlat, -90.0),
            self.lon_deg + dlon,
            min(self.lat_deg + dlat, 90.0),
        )

    def contains(self, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        lat = np.asarray(lat_deg, dtype=np.float64)
        lon = np.asarray(lon_deg, dtype=np.float64)
        if lat.size == 0:
            return np.zeros(lat.shape, dtype=bool)
        # Distance on the local tangent plane at the centre (exact to mm at city scale).
        n, e, _ = pymap3d.geodetic2ned(lat, lon, 0.0, self.lat_deg, self.lon_deg, 0.0)
        return np.hypot(n, e) <= self.radius_m

    def centre(self) -> tuple[float, float]:
        return (self.lat_deg, self.lon_deg)


Area = BBox | Circle


@dataclass(frozen=True)
class Candidates:
    """What practical-map selection needs of the landmarks of one area, as columns.

    ``impact`` is NaN where the landmark has no impact score yet.
    """

    ids: tuple[str, ...]
    lat_deg: npt.NDArray[np.float64]
    lon_deg: npt.NDArray[np.float64]
    impact: npt.NDArray[np.float64]
    status: tuple[str, ...]
    status_reason: tuple[str, ...]

    @classmethod
    def from_rows(cls, rows: Sequence[tuple[Any, ...]], area: Area | None = None
                  ) -> Candidates:
        """From ``(id, lat, lon, impact, status, status_reason)`` rows, keeping those
        inside ``area`` (exact test after an index's box pre-filter)."""
        n = len(rows)
        lat = np.fromiter((r[1] for r in rows), np.float64, n)
        lon = np.fromiter((r[2] for r in rows), np.float64, n)
        if area is not None and n:
            keep = area.contains(lat, lon)
            if not keep.all():
                return cls.from_rows([r for r, ok in zip(rows, keep.tolist(), strict=True)
                                      if ok])
        impact = np.fromiter((np.nan if r[3] is None else r[3] for r in rows), np.float64, n)
        return cls(tuple(r[0] for r in rows), lat, lon, impact,
                   tuple(r[4] for r in rows), tuple(r[5] for r in rows))

    @classmethod
    def from_landmarks(cls, landmarks: Sequence[Landmark]) -> Candidates:
        return cls.from_rows([(lm.id, lm.lat_deg, lm.lon_deg, lm.scores.impact, lm.status,
                               lm.status_reason) for lm in landmarks])


def parse_area(text: str) -> Area:
    """Parse ``bbox:MIN_LON,MIN_LAT,MAX_LON,MAX_LAT`` or ``circle:LAT,LON,RADIUS_M``.

    Raises ``ValueError`` with a one-line message on bad text.
    """
    kind, _, rest = text.partition(":")
    try:
        nums = [float(x) for x in rest.split(",")]
    except ValueError:
        nums = []
    if kind == "bbox" and len(nums) == 4 and all(map(math.isfinite, nums)):
        box = BBox(*nums)
        if (
            -180 <= box.min_lon_deg <= box.max_lon_deg <= 180
            and -90 <= box.min_lat_deg <= box.max_lat_deg <= 90
        ):
            return box
    if kind == "circle" and len(nums) == 3 and all(map(math.isfinite, nums)):
        lat, lon, radius = nums
        if -90 <= lat <= 90 and -180 <= lon <= 180 and radius > 0:
            return Circle(lat, lon, radius)
    raise ValueError(
        f"area {text!r}: expected bbox:MIN_LON,MIN_LAT,MAX_LON,MAX_LAT (degrees, min <= max) "
        "or circle:LAT,LON,RADIUS_M (radius > 0)"
    )


def filter_area(landmarks: list[Landmark], area: Area) -> list[Landmark]:
    """The landmarks lying inside ``area`` (exact test after an index's box pre-filter)."""
    if not landmarks:
        return []
    lat = np.fromiter((lm.lat_deg for lm in landmarks), np.float64, len(landmarks))
    lon = np.fromiter((lm.lon_deg for lm in landmarks), np.float64, len(landmarks))
    inside = area.contains(lat, lon)
    return [lm for lm, ok in zip(landmarks, inside.tolist(), strict=True) if ok]


def _spread_bits(v: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
    """Insert a zero bit between the low 16 bits of each value (Morton code helper)."""
    v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF)
    v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F)
    v = (v | (v << np.uint64(2))) & np.uint64(0x33333333)
    return (v | (v << np.uint64(1))) & np.uint64(0x55555555)


def spatial_order(lat_deg: npt.NDArray[np.float64], lon_deg: npt.NDArray[np.float64]
                  ) -> npt.NDArray[np.intp]:
    """Indices of the positions ``(lat_deg[i], lon_deg[i])`` in Morton (Z-curve) order.

    Bulk loads in this order keep neighbours together in the table and in the spatial
    index, which makes both the load and later area queries faster.
    """
    if len(lat_deg) < 2:
        return np.arange(len(lat_deg))

    def grid(x: npt.NDArray[np.float64]) -> npt.NDArray[np.uint64]:
        span = float(x.max() - x.min()) or 1.0
        return ((x - x.min()) * (65535.0 / span)).astype(np.uint64)

    key = _spread_bits(grid(lon_deg)) | (_spread_bits(grid(lat_deg)) << np.uint64(1))
    return np.argsort(key, kind="stable")
