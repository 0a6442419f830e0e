"""Landmark name <-> WGS84 <-> local NED (paper sec. 2.3, the name/coordinate table).

All conversions go through pymap3d (WGS84 ellipsoid); nothing here is hand-written
geodesy.  The local frame is NED about a configured origin, as everywhere in the project
(tracker/geometry.py).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pymap3d

from companion.core.landmark import Landmark
from companion.errors import InputError
from companion.landmarks.repository import LandmarkRepository
from tracker.pose.landmarks import corners_about, face_rotation

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LocalFrame:
    """Local NED frame whose origin is a WGS84 point (degrees; heights in metres AMSL, the
    datum of the EKF origin and of landmark ``alt_m``: pymap3d treats them as ellipsoidal,
    which only the difference of two heights reaches, docs/landmarks.md "Heights")."""

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def __post_init__(self) -> None:
        if not (-90.0 <= self.lat_deg <= 90.0 and -180.0 <= self.lon_deg <= 180.0):
            raise ValueError(f"origin: expected lat in [-90, 90] and lon in [-180, 180], "
                             f"got ({self.lat_deg}, {self.lon_deg})")

    def to_ned(self, lat_deg: npt.ArrayLike, lon_deg: npt.ArrayLike,
               alt_m: npt.ArrayLike) -> FloatArray:
        """WGS84 -> NED metres; shape (3,) for scalars, (N, 3) for arrays."""
        n, e, d = pymap3d.geodetic2ned(lat_deg, lon_deg, alt_m,
                                       self.lat_deg, self.lon_deg, self.alt_m)
        return np.stack([np.asarray(n), np.asarray(e), np.asarray(d)], axis=-1).astype(np.float64)

    def to_wgs84(self, north_m: npt.ArrayLike, east_m: npt.ArrayLike, down_m: npt.ArrayLike
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """NED metres -> (lat_deg, lon_deg, alt_m)."""
        lat, lon, alt = pymap3d.ned2geodetic(north_m, east_m, down_m,
                                             self.lat_deg, self.lon_deg, self.alt_m)
        return np.asarray(lat), np.asarray(lon), np.asarray(alt)


def facing_normal_ned(facing_deg: float | None) -> FloatArray:
    """Unit outward normal of the landmark face in NED: ``(cos a, sin a, 0)`` for a vertical
    face with azimuth ``a`` (from north, clockwise), ``(0, 0, -1)`` for one lying flat."""
    return np.asarray(face_rotation(facing_deg)[:, 2], dtype=np.float64)


def corners_ned(lm: Landmark, frame: LocalFrame) -> FloatArray:
    """The face's corners in NED, (4, 3): top-left, top-right, bottom-right, bottom-left as
    seen by a viewer in front of the face (for a flat landmark: seen from above, north up);
    :func:`tracker.pose.landmarks.corners_about` is the one definition."""
    centre = frame.to_ned(lm.lat_deg, lm.lon_deg, lm.alt_m)
    return corners_about(centre, lm.width_m, lm.height_m, lm.facing_deg)


def pick_one(key: str, by_id: Landmark | None, named: list[Landmark]) -> Landmark:
    """The landmark a user means by ``key``: the one with that id, else the only one
    with that name; a missing or ambiguous name is an :class:`InputError`."""
    if by_id is not None:
        return by_id
    if len(named) == 1:
        return named[0]
    if not named:
        raise InputError(f"landmark {key!r}: no landmark has this id or name")
    ids = ", ".join(lm.id for lm in named[:5])
    raise InputError(f"landmark {key!r}: {len(named)} landmarks share this name "
                     f"({ids}{', ...' if len(named) > 5 else ''}); use an id")


class NameTable:
    """The mapping table between landmark names (or ids) and coordinates."""

    def __init__(self, landmarks: Iterable[Landmark], frame: LocalFrame) -> None:
        self.frame = frame
        self._by_id: dict[str, Landmark] = {}
        self._by_name: dict[str, list[Landmark]] = {}
        for lm in landmarks:
            self._by_id[lm.id] = lm
            self._by_name.setdefault(lm.name, []).append(lm)

    @classmethod
    def from_repository(cls, repo: LandmarkRepository, frame: LocalFrame) -> NameTable:
        return cls(repo.iter_all(with_appearance=False), frame)

    def lookup(self, key: str) -> Landmark:
        """The landmark with this id, else the one landmark with this name."""
        return pick_one(key, self._by_id.get(key), self._by_name.get(key, []))

    def wgs84(self, key: str) -> tuple[float, float, float]:
        lm = self.lookup(key)
        return lm.lat_deg, lm.lon_deg, lm.alt_m

    def ned(self, key: str) -> FloatArray:
        lm = self.lookup(key)
        return self.frame.to_ned(lm.lat_deg, lm.lon_deg, lm.alt_m)

    def nearest(self, north_m: float, east_m: float, down_m: float = 0.0
                ) -> tuple[Landmark, float]:
        """The landmark nearest to a NED point, and its 3-D distance in metres."""
        if not self._by_id:
            raise InputError("landmark table is empty")
        lms = list(self._by_id.values())
        pos = self.frame.to_ned(np.array([lm.lat_deg for lm in lms]),
                                np.array([lm.lon_deg for lm in lms]),
                                np.array([lm.alt_m for lm in lms]))
        dist = np.linalg.norm(pos - np.array([north_m, east_m, down_m]), axis=1)
        k = int(np.argmin(dist))
        return lms[k], float(dist[k])
