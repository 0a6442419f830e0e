"""Landmark geometry: the face frame and the four corners in NED.

Face frame of a landmark (right-handed): origin at its centre, x to the right and y up as
seen by a viewer standing in front of it, z along the outward normal (towards the viewer).

* Upright landmark (``facing_deg`` = psi): normal ``n = (cos psi, sin psi, 0)`` in NED,
  up ``u = (0, 0, -1)``, right ``r = -n x u``.
* Flat landmark (``facing_deg`` is ``None``): normal up ``(0, 0, -1)``, its top edge points
  north, so x = east, y = north.

Corner order (the order of :attr:`Observation.corners_px` too) is OpenCV's
``SOLVEPNP_IPPE_SQUARE`` order in the face frame:

    0 top-left (-w/2, +h/2), 1 top-right (+w/2, +h/2),
    2 bottom-right (+w/2, -h/2), 3 bottom-left (-w/2, -h/2).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from tracker.geometry import FloatArray
from tracker.pose.types import MapLandmark


def face_rotation(facing_deg: float | None) -> FloatArray:
    """``R_ned_face``: columns are the face x (right), y (up) and z (normal) in NED."""
    if facing_deg is None:
        return np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    psi = np.deg2rad(facing_deg)
    c, s = float(np.cos(psi)), float(np.sin(psi))
    # n = (c, s, 0); u = (0, 0, -1); r = -n x u = (s, -c, 0)
    return np.array([[s, 0.0, c], [-c, 0.0, s], [0.0, -1.0, 0.0]])


def face_corners(width_m: float, height_m: float) -> FloatArray:
    """4x3 corners in the face frame, in the documented order (z = 0)."""
    w, h = 0.5 * width_m, 0.5 * height_m
    return np.array([[-w, h, 0.0], [w, h, 0.0], [w, -h, 0.0], [-w, -h, 0.0]])


@lru_cache(maxsize=4096)
def landmark_normal_ned(landmark: MapLandmark) -> FloatArray:
    """Outward unit normal of the face in NED (read-only, cached per landmark)."""
    n = face_rotation(landmark.facing_deg)[:, 2].copy()
    n.setflags(write=False)
    return n


def corners_about(centre_ned: FloatArray | tuple[float, float, float], width_m: float,
                  height_m: float, facing_deg: float | None) -> FloatArray:
    """4x3 NED corners of a face centred at ``centre_ned``: ``c_i = centre + R_ned_face p_i``.

    The one definition of a landmark's corners: the pose solver, the simulated world and
    the landmark database all use it.
    """
    r = face_rotation(facing_deg)
    centre = np.asarray(centre_ned, dtype=np.float64)
    return np.asarray(centre + face_corners(width_m, height_m) @ r.T, dtype=np.float64)


@lru_cache(maxsize=4096)
def landmark_corners_ned(landmark: MapLandmark) -> FloatArray:
    """4x3 NED corners of a map landmark (read-only, cached)."""
    out = corners_about(landmark.position_ned_m, landmark.width_m, landmark.height_m,
                        landmark.facing_deg)
    out.setflags(write=False)
    return out
