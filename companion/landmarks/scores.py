"""Admission scores and the landmark impact score (docs/landmarks.md explains each factor).

* distinctiveness ``d = VR / (VR + vr_half)`` where ``VR`` is the best variance ratio of
  the reference image's landmark box against its surroundings, computed by the tracker's
  feature ranking (``tracker.distinctiveness.best_variance_ratio``; not written twice here);
* flatness ``f = 1 / (1 + (rms / flatness_tolerance_m)^2)`` with ``rms`` the RMS distance
  of the measured 3-D points from their least-squares plane;
* static ``s = (consistent / n) * min(1, n / static_min_sightings)`` over ``n``
  sightings, ``consistent`` = those within ``static_tolerance_m`` of the recorded position;
* impact ``I = exp(sum_k w_k ln x_k / sum_k w_k)``: the weighted geometric mean of the
  three factors (a factor that is not known counts as ``unknown_score``).

A factor that cannot be measured keeps its declared value (from the map's ``scores``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import cv2
import numpy as np
import numpy.typing as npt
import pymap3d

from companion.core.landmark import Appearance, Landmark, Point3, Scores, Status
from companion.landmarks.config import LandmarksConfig
from companion.landmarks.repository import ScoreUpdate
from tracker.distinctiveness import best_variance_ratio

#: ``(image_bgr uint8 HxWx3, (x, y, w, h) box in pixels) -> best variance ratio >= 0``.
VrScorer = Callable[[npt.NDArray[np.uint8], tuple[int, int, int, int]], float]


def tracker_vr_scorer() -> VrScorer:
    """The tracker's own ranking, :func:`tracker.distinctiveness.best_variance_ratio`."""
    return best_variance_ratio


def distinctiveness_from_vr(vr: float, vr_half: float) -> float:
    """Map a variance ratio in [0, inf) onto [0, 1): ``d = VR / (VR + vr_half)``."""
    vr = max(float(vr), 0.0)
    return vr / (vr + vr_half)


def measure_distinctiveness(app: Appearance, scorer: VrScorer, vr_half: float) -> float:
    """Decode the reference image and score its landmark box (default: central half)."""
    decoded = cv2.imdecode(np.frombuffer(app.data, np.uint8), cv2.IMREAD_COLOR)
    if decoded is None:
        raise ValueError(f"appearance: cannot decode the {app.media_type} image")
    image = np.ascontiguousarray(decoded, dtype=np.uint8)
    h, w = image.shape[:2]
    x, y, bw, bh = app.box_px or (w // 4, h // 4, max(w // 2, 1), max(h // 2, 1))
    if x < 0 or y < 0 or bw <= 0 or bh <= 0 or x + bw > w or y + bh > h:
        raise ValueError(f"appearance_box: {(x, y, bw, bh)} lies outside the {w}x{h} image")
    return distinctiveness_from_vr(scorer(image, (x, y, bw, bh)), vr_half)


def plane_fit_rms_m(points_m: npt.ArrayLike) -> float:
    """RMS distance of N >= 3 points (N x 3, metres) from their least-squares plane."""
    p = np.asarray(points_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 3:
        raise ValueError(f"points_m: expected an N x 3 array with N >= 3, got shape {p.shape}")
    centred = p - p.mean(axis=0)
    # The plane's normal is the right singular vector of the smallest singular value s3;
    # the sum of squared distances to that plane is s3^2, so rms = s3 / sqrt(N).
    s = np.linalg.svd(centred, compute_uv=False)
    return float(s[-1] / math.sqrt(p.shape[0]))


def flatness_from_points(points_m: npt.ArrayLike, tolerance_m: float) -> float:
    """``f = 1 / (1 + (rms / tolerance)^2)``: 1 for a plane, 0.5 at rms = tolerance."""
    r = plane_fit_rms_m(points_m) / tolerance_m
    return 1.0 / (1.0 + r * r)


def static_from_sightings(lm: Landmark, sightings: Sequence[Point3], tolerance_m: float,
                          min_sightings: int) -> float:
    """``s = (consistent / n) * min(1, n / min_sightings)`` over ``(lon, lat, alt)`` sightings."""
    if not sightings:
        raise ValueError("sightings: expected at least one")
    s = np.asarray(sightings, dtype=np.float64)
    n_m, e_m, d_m = pymap3d.geodetic2ned(s[:, 1], s[:, 0], s[:, 2],
                                         lm.lat_deg, lm.lon_deg, lm.alt_m)
    consistent = int(np.count_nonzero(np.sqrt(n_m**2 + e_m**2 + d_m**2) <= tolerance_m))
    n = len(sightings)
    return (consistent / n) * min(1.0, n / min_sightings)


def impact_score(factors: Sequence[float], weights: Sequence[float]) -> float:
    """Weighted geometric mean ``exp(sum w ln x / sum w)``; 0 if any weighted factor is 0."""
    total = float(sum(weights))
    if total <= 0.0:
        raise ValueError("weights: at least one impact weight must be > 0")
    acc = 0.0
    for x, w in zip(factors, weights, strict=True):
        if w == 0.0:
            continue
        if x <= 0.0:
            return 0.0
        acc += w * math.log(min(x, 1.0))
    return math.exp(acc / total)


def _measured(lm: Landmark, config: LandmarksConfig, scorer: VrScorer | None
              ) -> tuple[Scores, list[str]]:
    """Measure what can be measured, else keep the declared values; notes name problems."""
    notes: list[str] = []
    d, f, s = lm.scores.distinctiveness, lm.scores.flatness, lm.scores.static
    if lm.appearance is not None and scorer is not None:
        try:
            d = measure_distinctiveness(lm.appearance, scorer, config.vr_half)
        except ValueError as err:
            notes.append(str(err))
    if len(lm.points_m) >= 3:
        f = flatness_from_points(lm.points_m, config.flatness_tolerance_m)
    if lm.sightings:
        s = static_from_sightings(lm, lm.sightings, config.static_tolerance_m,
                                  config.static_min_sightings)
    return Scores(d, f, s), notes


def evaluate(lm: Landmark, config: LandmarksConfig, scorer: VrScorer | None,
             restatus: bool = False) -> ScoreUpdate:
    """New scores for one landmark, and its admission status.

    Only a ``candidate`` (or any landmark with ``restatus``) gets a new status:
    ``approved`` when every factor and the impact reach their thresholds, ``rejected``
    naming the failed criteria, or still ``candidate`` when a factor is unknown.
    """
    m, notes = _measured(lm, config, scorer)
    w, t = config.weights, config.thresholds
    factors = {"distinctiveness": m.distinctiveness, "flatness": m.flatness, "static": m.static}
    filled = [config.unknown_score if v is None else v for v in factors.values()]
    impact = impact_score(filled, (w.distinctiveness, w.flatness, w.static))
    scores = Scores(m.distinctiveness, m.flatness, m.static, impact)
    if lm.status != "candidate" and not restatus:
        return ScoreUpdate(lm.id, scores, lm.status, lm.status_reason)
    minima = {"distinctiveness": t.distinctiveness_min, "flatness": t.flatness_min,
              "static": t.static_min}
    failed = [f"{k} {v:.2f} < {minima[k]:.2f}" for k, v in factors.items()
              if v is not None and v < minima[k]]
    if impact < t.impact_min:
        failed.append(f"impact {impact:.2f} < {t.impact_min:.2f}")
    unknown = [k for k, v in factors.items() if v is None]
    status: Status
    if failed:
        status, reason = "rejected", "; ".join(failed)
    elif unknown:
        status, reason = "candidate", "unknown: " + ", ".join(unknown)
    else:
        status, reason = "approved", "meets every admission threshold"
    if notes:
        reason += " (" + "; ".join(notes) + ")"
    return ScoreUpdate(lm.id, scores, status, reason)
