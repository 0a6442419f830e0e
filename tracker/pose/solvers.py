"""Initial pose estimates, each returning ``x0 = (p_ned, rpy)`` for :func:`refine_pose`.

* :func:`ippe_candidates` - one planar landmark with four corners (OpenCV IPPE / IPPE_SQUARE);
  returns both planar solutions (the flip ambiguity).
* :func:`pnp_ransac` - two or more landmarks' points without attitude (AP3P in RANSAC, EPnP
  refit); :func:`pnp_all_points` - SQPnP on every point (the refit's fallback on coplanar points).
* :func:`bearing_least_squares` - known camera rotation: every bearing ``b_i`` gives
  ``[b_i]x (L_i - p) = 0``; altitude and laser add linear rows; solved by least squares.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
import numpy.typing as npt

from tracker.geometry import FloatArray, rpy_from_rotation
from tracker.pose.refine import RangePrior

BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Candidate:
    """An initial pose: state (6,), and the RMS reprojection error OpenCV reported (px)."""

    x0: FloatArray
    rms_px: float


def state_from_camera(
    r_ned_cam: FloatArray, cam_ned: FloatArray, r_body_cam: FloatArray
) -> FloatArray:
    """``R_ned_body = R_ned_cam R_body_cam^T``; the vehicle sits at the camera centre."""
    rpy = rpy_from_rotation(r_ned_cam @ r_body_cam.T)
    return np.concatenate([cam_ned, np.asarray(rpy)])


def _camera_from_opencv(
    rvec: object, tvec: object, r_ned_obj: FloatArray, obj_origin_ned: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """OpenCV ``X_c = R_co X_o + t`` -> (``R_ned_cam``, camera centre in NED)."""
    r_co, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    r_ned_cam = r_ned_obj @ r_co.T
    cam_obj = -r_co.T @ np.asarray(tvec, dtype=np.float64).reshape(3)
    return r_ned_cam, obj_origin_ned + r_ned_obj @ cam_obj


def ippe_candidates(
    face_points: FloatArray,
    pixels_distorted: FloatArray,
    k: FloatArray,
    dist: FloatArray,
    r_ned_face: FloatArray,
    centre_ned: FloatArray,
    r_body_cam: FloatArray,
    square: bool,
) -> list[Candidate]:
    """Both IPPE solutions for one planar landmark, best first (OpenCV's order).

    ``face_points`` are the 4 corners in the face frame in the IPPE_SQUARE order.
    """
    flags = cv2.SOLVEPNP_IPPE_SQUARE if square else cv2.SOLVEPNP_IPPE
    try:
        n, rvecs, tvecs, errs = cv2.solvePnPGeneric(
            face_points.reshape(-1, 1, 3), pixels_distorted.reshape(-1, 1, 2), k, dist, flags=flags
        )
    except cv2.error:
        return []
    out = []
    for i in range(int(n)):
        r_nc, cam = _camera_from_opencv(rvecs[i], tvecs[i], r_ned_face, centre_ned)
        err = float(np.asarray(errs).reshape(-1)[i]) if errs is not None else 0.0
        out.append(Candidate(state_from_camera(r_nc, cam, r_body_cam), err))
    return sorted(out, key=lambda c: c.rms_px)


def pnp_ransac(
    points_ned: FloatArray,
    pixels_distorted: FloatArray,
    k: FloatArray,
    dist: FloatArray,
    r_body_cam: FloatArray,
    threshold_px: float,
    iterations: int,
    confidence: float,
) -> tuple[Candidate, BoolArray] | None:
    """RANSAC PnP on NED points (centred for conditioning); returns the pose and inlier mask.

    AP3P on minimal samples: 79 against 188 us for SQPnP on 32 points, the same inliers
    (2026-11-25).  The mask is the best sample's; the pose is OpenCV's EPnP refit on it.
    """
    origin = points_ned.mean(axis=0)
    obj = (points_ned - origin).reshape(-1, 1, 3)
    try:
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj,
            pixels_distorted.reshape(-1, 1, 2),
            k,
            dist,
            iterationsCount=iterations,
            reprojectionError=threshold_px,
            confidence=confidence,
            flags=cv2.SOLVEPNP_AP3P,
        )
    except cv2.error:
        return None
    if not ok or inliers is None:
        return None
    mask = np.zeros(points_ned.shape[0], dtype=bool)
    mask[np.asarray(inliers).reshape(-1)] = True
    r_nc, cam = _camera_from_opencv(rvec, tvec, np.eye(3), origin)
    return Candidate(state_from_camera(r_nc, cam, r_body_cam), 0.0), mask


def pnp_all_points(
    points_ned: FloatArray,
    pixels_distorted: FloatArray,
    k: FloatArray,
    dist: FloatArray,
    r_body_cam: FloatArray,
) -> Candidate | None:
    """SQPnP (globally optimal for its algebraic cost) on every point, no outlier rejection."""
    origin = points_ned.mean(axis=0)
    obj = (points_ned - origin).reshape(-1, 1, 3)
    try:
        ok, rvec, tvec = cv2.solvePnP(
            obj, pixels_distorted.reshape(-1, 1, 2), k, dist, flags=cv2.SOLVEPNP_SQPNP
        )
    except cv2.error:
        return None
    if not ok:
        return None
    r_nc, cam = _camera_from_opencv(rvec, tvec, np.eye(3), origin)
    return Candidate(state_from_camera(r_nc, cam, r_body_cam), 0.0)


def bearings_ned(pixels_ideal: FloatArray, k: FloatArray, r_ned_cam: FloatArray) -> FloatArray:
    """Unit bearings in NED: ``b = R_ned_cam K^-1 [u, v, 1]^T / |.|``."""
    rays = np.column_stack(
        [
            (pixels_ideal[:, 0] - k[0, 2]) / k[0, 0],
            (pixels_ideal[:, 1] - k[1, 2]) / k[1, 1],
            np.ones(pixels_ideal.shape[0]),
        ]
    )
    b = rays @ r_ned_cam.T
    return np.asarray(b / np.linalg.norm(b, axis=1, keepdims=True))


def bearing_least_squares(
    points_ned: FloatArray,
    bearings: FloatArray,
    r_ned_body: FloatArray,
    altitude_down_m: float | None = None,
    range_prior: RangePrior | None = None,
    min_singular: float = 1e-6,
) -> FloatArray | None:
    """Camera position from bearings with known rotation (linear least squares).

    Rows: ``[b_i]x p = [b_i]x L_i`` per point; ``p_d = d_0`` for a known altitude;
    ``n.p = n.c - d n.(R_nb a_b)`` for a laser meeting the plane (n, c); the altitude and
    laser rows carry weight 10.  Solved by the normal equations: with unit ``b_i``,
    ``[b_i]x^T [b_i]x = I - b_i b_i^T``.  Returns ``None`` when the rows do not fix all
    three coordinates (smallest singular value below ``min_singular`` of the largest).
    """
    n = bearings.shape[0]
    origin = points_ned.mean(axis=0)  # solve for p - origin: no cancellation far from home
    rel = points_ned - origin
    ata = n * np.eye(3) - bearings.T @ bearings
    atb = rel.sum(axis=0) - bearings.T @ np.einsum("ij,ij->i", bearings, rel)
    if altitude_down_m is not None:
        ata[2, 2] += 100.0
        atb[2] += 100.0 * (altitude_down_m - origin[2])
    if range_prior is not None:
        nrm = range_prior.plane_normal
        na = float(nrm @ (r_ned_body @ range_prior.axis_body))
        ata += 100.0 * np.outer(nrm, nrm)
        atb += 100.0 * (nrm @ (range_prior.plane_point - origin)
                        - range_prior.distance_m * na) * nrm
    lam, vec = np.linalg.eigh(ata)  # lam: squared singular values of the stacked rows
    if lam[0] <= 0.0 or lam[0] < min_singular**2 * lam[-1]:
        return None
    return np.asarray(origin + vec @ ((vec.T @ atb) / lam), dtype=np.float64)


@lru_cache(maxsize=32)
def _pairs(n: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Indices ``(i, j)``, ``i < j``, of every pair among ``n`` (read-only, cached)."""
    i, j = np.triu_indices(n, 1)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j


def bearing_consensus(
    points_ned: FloatArray,
    bearings: FloatArray,
    landmark_index: npt.NDArray[np.int64],
    threshold_rad: float,
) -> FloatArray | None:
    """Per-landmark angular error (rad) under the best two-landmark hypothesis.

    RANSAC over all landmark pairs with a known rotation, vectorised: each landmark is
    reduced to its mean point ``C_g`` and mean bearing ``u_g``; a pair's position is the
    midpoint of the shortest segment between the rays ``C_i - s u_i`` and ``C_j - t u_j``;
    the pair leaving the most landmarks within ``threshold_rad`` (ties: the smallest summed
    error) wins.  ``None`` when no pair is joined by a third landmark (no majority).
    """
    n_groups = int(landmark_index.max()) + 1
    if n_groups < 3:
        return None
    i, j = _pairs(n_groups)
    member = (landmark_index == np.arange(n_groups)[:, None]).astype(np.float64)  # G x N
    c = (member @ points_ned) / member.sum(axis=1, keepdims=True)  # mean point per landmark
    u = member @ bearings
    u = u / np.linalg.norm(u, axis=1, keepdims=True)  # mean bearing per landmark
    # closest points of X = C_i - s u_i and X = C_j - t u_j (unit directions, b = u_i.u_j)
    ci, cj, ui, uj = c[i], c[j], u[i], u[j]
    w0 = ci - cj
    b = np.einsum("pk,pk->p", ui, uj)
    d = -np.einsum("pk,pk->p", ui, w0)
    e = -np.einsum("pk,pk->p", uj, w0)
    denom = 1.0 - b * b
    ok = denom > 1e-9
    denom = np.where(ok, denom, 1.0)
    s = (b * e - d) / denom
    t = (e - b * d) / denom
    pos = 0.5 * ((ci - s[:, None] * ui) + (cj - t[:, None] * uj))  # pairs x 3
    rel = c[None, :, :] - pos[:, None, :]  # pairs x groups x 3
    cos = np.einsum("pgk,gk->pg", rel, u) / np.maximum(np.linalg.norm(rel, axis=2), 1e-12)
    err = np.arccos(np.clip(cos, -1.0, 1.0))
    err[~ok] = np.pi
    inl = err < threshold_rad
    count = inl.sum(axis=1)
    score = count * 1e3 - np.where(inl, err, 0.0).sum(axis=1)  # count, then error
    best = int(np.argmax(score))
    # a pair always fits itself: only a third landmark agreeing makes a consensus
    return np.asarray(err[best]) if count[best] >= 3 else None
