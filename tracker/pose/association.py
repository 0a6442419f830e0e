"""Naming unlabelled detections: project the map through a predicted pose, gate, compare.

For every unlabelled observation and every map landmark of its category that the predicted
camera could see (in front, face turned towards the camera, inside the image plus a
margin), the association cost is

    c = (z - h)^T S^-1 (z - h) + w_a * d_B(sig_obs, sig_map)^2

with ``z`` the observed centre, ``h`` the predicted centre and
``S = J_p (s_p^2 I) J_p^T + (f s_att)^2 I + s_c^2 I`` (position, attitude and centre
noise).  Gates: Mahalanobis term below ``gate_chi2``; box-size log ratio; Bhattacharyya
distance.  A match is accepted only when no other candidate (another landmark for this
detection, or another detection for this landmark) comes within ``ambiguity_margin`` of
its cost; otherwise the detection is reported as ambiguous, never guessed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tracker.camera import CameraModel
from tracker.geometry import FloatArray
from tracker.pose.config import AssociationConfig, PoseConfig
from tracker.pose.landmarks import landmark_corners_ned, landmark_normal_ned
from tracker.pose.types import MapLandmark, Observation, PosePrior


@dataclass(frozen=True)
class Match:
    """Observation ``observation_index`` is landmark ``landmark_id`` (cost 0 when labelled)."""

    observation_index: int
    landmark_id: str
    cost: float = 0.0


@dataclass(frozen=True)
class Ambiguity:
    """An observation that more than one landmark (or a rival detection) explains."""

    observation_index: int
    candidate_ids: tuple[str, ...]
    reason: str


@dataclass(frozen=True)
class Association:
    """Matches, ambiguities and observations left unnamed (with notes saying why)."""

    matches: tuple[Match, ...]
    ambiguities: tuple[Ambiguity, ...]
    unmatched: tuple[int, ...]
    notes: tuple[str, ...]


@dataclass(frozen=True)
class _Prediction:
    centre_px: FloatArray
    box_size_px: float
    cov_px: FloatArray


def bhattacharyya_distance(p: Sequence[float], q: Sequence[float]) -> float:
    """``d = sqrt(1 - sum sqrt(p_i q_i))`` of two histograms normalised to sum 1."""
    a, b = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    if a.shape != b.shape or a.sum() <= 0 or b.sum() <= 0:
        return 1.0
    rho = float(np.sum(np.sqrt((a / a.sum()) * (b / b.sum()))))
    return math.sqrt(max(0.0, 1.0 - rho))


def predict_landmark(
    landmark: MapLandmark,
    camera: CameraModel,
    prior: PosePrior,
    cfg: AssociationConfig,
    centre_sigma_px: float = 2.0,
) -> _Prediction | None:
    """Predicted centre, box size and pixel covariance, or ``None`` when not visible."""
    p = np.asarray(prior.position_ned_m, dtype=np.float64)
    centre = np.asarray(landmark.position_ned_m, dtype=np.float64)
    if float(landmark_normal_ned(landmark) @ (p - centre)) <= 0.0:
        return None  # seen from behind
    pts = np.vstack([centre, landmark_corners_ned(landmark)])
    xc = camera.world_to_camera(pts, p, prior.attitude_rpy_rad)
    if np.any(xc[:, 2] <= 0.05):
        return None
    uv = camera.project_camera_points(xc)
    m = cfg.image_margin_px
    if not (-m <= uv[0, 0] <= camera.width + m and -m <= uv[0, 1] <= camera.height + m):
        return None
    span = uv[1:].max(axis=0) - uv[1:].min(axis=0)
    z = xc[0, 2]
    # d pixel / d camera point, then d camera point / d position = -R_cam_ned
    j_xc = np.array(
        [
            [camera.fx / z, 0.0, -camera.fx * xc[0, 0] / z**2],
            [0.0, camera.fy / z, -camera.fy * xc[0, 1] / z**2],
        ]
    )
    r_ned_cam = camera.world_to_camera(np.eye(3), np.zeros(3), prior.attitude_rpy_rad)
    j_p = -j_xc @ r_ned_cam.T
    f = max(camera.fx, camera.fy)
    cov = prior.position_sigma_m**2 * (j_p @ j_p.T) + (
        (f * prior.attitude_sigma_rad) ** 2 + centre_sigma_px**2
    ) * np.eye(2)
    return _Prediction(uv[0], float(np.sqrt(max(span[0] * span[1], 1e-9))), cov)


def _cost(
    obs: Observation, lm: MapLandmark, pred: _Prediction, cfg: AssociationConfig
) -> float | None:
    """Association cost, or ``None`` when a gate rejects the pair."""
    innov = np.asarray(obs.centre_px, dtype=np.float64) - pred.centre_px
    maha = float(innov @ np.linalg.solve(pred.cov_px, innov))
    if maha > cfg.gate_chi2:
        return None
    obs_size = math.sqrt(max(obs.box_wh_px[0] * obs.box_wh_px[1], 1e-9))
    if abs(math.log(obs_size / pred.box_size_px)) > cfg.max_log_size_ratio:
        return None
    cost = maha
    if obs.signature is not None and lm.signature is not None:
        d = bhattacharyya_distance(obs.signature, lm.signature)
        if d > cfg.max_appearance_distance:
            return None
        cost += cfg.appearance_weight * d * d
    return cost


def associate(
    observations: Sequence[Observation],
    landmarks: Sequence[MapLandmark],
    camera: CameraModel,
    prior: PosePrior | None,
    config: PoseConfig | None = None,
) -> Association:
    """Name every observation: labelled ones by id, unlabelled ones by gated projection.

    Observations below ``config.min_confidence`` are left unmatched (with a note).
    """
    full = config or PoseConfig()
    cfg = full.association
    by_id = {lm.landmark_id: lm for lm in landmarks}
    matches: list[Match] = []
    notes: list[str] = []
    unmatched: list[int] = []
    pending: list[int] = []
    for i, obs in enumerate(observations):
        if obs.confidence < full.min_confidence:
            unmatched.append(i)
            notes.append(f"observation {i}: confidence {obs.confidence:.2f} below min_confidence")
        elif obs.landmark_id is None:
            pending.append(i)
        elif obs.landmark_id in by_id:
            matches.append(Match(i, obs.landmark_id))
        else:
            unmatched.append(i)
            notes.append(f"observation {i}: landmark {obs.landmark_id!r} is not in the map")
    claimed = {m.landmark_id for m in matches}
    if not pending:
        return Association(tuple(matches), (), tuple(unmatched), tuple(notes))
    if prior is None:
        notes.append(f"{len(pending)} unlabelled observation(s) and no predicted pose")
        return Association(tuple(matches), (), tuple(unmatched + pending), tuple(notes))
    costs = _cost_table(
        observations, pending, landmarks, claimed, camera, prior, full.centre_sigma_px, cfg
    )
    new, ambiguities, left = _resolve(costs, cfg.ambiguity_margin)
    for i in left:
        notes.append(f"observation {i}: no map landmark passes the gates")
    unmatched += left
    return Association(
        tuple(matches + new), tuple(ambiguities), tuple(sorted(unmatched)), tuple(notes)
    )


def _cost_table(
    observations: Sequence[Observation],
    pending: list[int],
    landmarks: Sequence[MapLandmark],
    claimed: set[str],
    camera: CameraModel,
    prior: PosePrior | None,
    centre_sigma_px: float,
    cfg: AssociationConfig,
) -> dict[int, dict[str, float]]:
    """Gated costs ``{observation index: {landmark id: cost}}``."""
    assert prior is not None
    preds = {}
    for lm in landmarks:
        if lm.landmark_id not in claimed:
            pred = predict_landmark(lm, camera, prior, cfg, centre_sigma_px)
            if pred is not None:
                preds[lm.landmark_id] = (lm, pred)
    table: dict[int, dict[str, float]] = {}
    for i in pending:
        obs = observations[i]
        row = {}
        for lid, (lm, pred) in preds.items():
            if obs.category is not None and lm.category != obs.category:
                continue
            c = _cost(obs, lm, pred, cfg)
            if c is not None:
                row[lid] = c
        table[i] = row
    return table


def _resolve(
    table: dict[int, dict[str, float]], margin: float
) -> tuple[list[Match], list[Ambiguity], list[int]]:
    """Accept each detection's best landmark only if no rival is within ``margin``."""
    matches, ambiguities, left = [], [], []
    for i, row in table.items():
        if not row:
            left.append(i)
            continue
        ranked = sorted(row.items(), key=lambda kv: kv[1])
        best_id, best = ranked[0]
        rivals = [lid for lid, c in ranked[1:] if c - best < margin]
        rival_obs = [
            j
            for j, other in table.items()
            if j != i and best_id in other and other[best_id] - best < margin
        ]
        if rivals:
            ids = (best_id, *rivals)
            ambiguities.append(Ambiguity(i, ids, f"{len(ids)} landmarks fit within the margin"))
        elif rival_obs:
            ambiguities.append(
                Ambiguity(i, (best_id,), f"observations {rival_obs} also fit {best_id!r}")
            )
        else:
            matches.append(Match(i, best_id, best))
    return matches, ambiguities, left
