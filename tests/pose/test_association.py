"""Association: gated projection names detections; ambiguity is reported, never guessed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tracker.camera import CameraModel
from tracker.pose import (
    MapLandmark,
    Observation,
    PoseConfig,
    PoseFix,
    PosePrior,
    associate,
    solve_pose,
)
from tracker.pose.association import bhattacharyya_distance

from .conftest import TRUE_P, TRUE_RPY, assert_exact, see, wall


def _prior(offset: tuple[float, float, float], sigma_m: float, sigma_deg: float) -> PosePrior:
    n, e, d = (float(v) for v in TRUE_P + np.asarray(offset))
    return PosePrior((n, e, d), TRUE_RPY, sigma_m, float(np.deg2rad(sigma_deg)))


PRIOR = _prior((0.3, -0.2, 0.1), 0.5, 1.0)


def _unlabelled(camera: CameraModel) -> tuple[tuple[MapLandmark, ...], list[Observation]]:
    lms = wall()
    return lms, [replace(o, landmark_id=None) for o in see(lms, camera)]


def test_unlabelled_detections_are_named_from_a_predicted_pose(camera: CameraModel) -> None:
    lms, obs = _unlabelled(camera)
    result = associate(obs, lms, camera, PRIOR)
    assert {(m.observation_index, m.landmark_id) for m in result.matches} == {
        (0, "A"),
        (1, "B"),
        (2, "C"),
        (3, "D"),
    }
    assert not result.ambiguities and not result.unmatched


def test_solve_pose_uses_the_association(camera: CameraModel) -> None:
    lms, obs = _unlabelled(camera)
    fix = solve_pose(obs, lms, camera, 0, prior=PRIOR)
    assert isinstance(fix, PoseFix) and set(fix.landmark_ids) == {"A", "B", "C", "D"}
    assert_exact(fix, TRUE_P, TRUE_RPY)


def test_without_a_predicted_pose_unlabelled_detections_stay_unnamed(
    camera: CameraModel,
) -> None:
    lms, obs = _unlabelled(camera)
    result = associate(obs, lms, camera, None)
    assert not result.matches and result.unmatched == (0, 1, 2, 3)
    assert any("no predicted pose" in n for n in result.notes)


def test_a_wrong_category_is_not_matched(camera: CameraModel) -> None:
    lms, obs = _unlabelled(camera)
    obs[0] = replace(obs[0], category="poster")
    result = associate(obs, lms, camera, PRIOR)
    assert 0 in result.unmatched and "A" not in {m.landmark_id for m in result.matches}


def _twins(
    camera: CameraModel,
) -> tuple[tuple[MapLandmark, ...], list[Observation], PosePrior]:
    """Two identical signs 0.8 m apart; a loose prior cannot tell which is which."""
    lms = (
        MapLandmark("T1", (20.0, 0.0, -5.0), 0.6, 0.6, 180.0, "sign", (0.7, 0.2, 0.1)),
        MapLandmark("T2", (20.0, 0.8, -5.0), 0.6, 0.6, 180.0, "sign", (0.1, 0.2, 0.7)),
    )
    obs = [replace(o, landmark_id=None, signature=None) for o in see(lms[:1], camera)]
    loose = _prior((0.0, 0.0, 0.0), 2.0, 2.0)
    return lms, obs, loose


def test_two_landmarks_that_fit_equally_are_reported_as_ambiguous(camera: CameraModel) -> None:
    lms, obs, loose = _twins(camera)
    result = associate(obs, lms, camera, loose)
    assert not result.matches
    assert len(result.ambiguities) == 1
    assert set(result.ambiguities[0].candidate_ids) == {"T1", "T2"}
    fix = solve_pose(obs, lms, camera, 0, prior=loose)
    assert not isinstance(fix, PoseFix)
    assert any("ambiguous" in n for n in fix.notes)


def test_the_appearance_signature_resolves_the_ambiguity(camera: CameraModel) -> None:
    lms, obs, loose = _twins(camera)
    obs = [replace(obs[0], signature=(0.68, 0.22, 0.1))]
    result = associate(obs, lms, camera, loose)
    assert [m.landmark_id for m in result.matches] == ["T1"] and not result.ambiguities


def test_two_detections_competing_for_one_landmark_are_not_guessed(
    camera: CameraModel,
) -> None:
    lms, obs, loose = _twins(camera)
    only = lms[:1]
    twin = replace(obs[0], centre_px=(obs[0].centre_px[0] + 2.0, obs[0].centre_px[1]))
    result = associate([obs[0], twin], only, camera, loose)
    assert not result.matches and len(result.ambiguities) == 2


def test_a_landmark_seen_from_behind_is_not_a_candidate(camera: CameraModel) -> None:
    lms, obs = _unlabelled(camera)
    turned = tuple(replace(lm, facing_deg=0.0) for lm in lms)  # faces away from the camera
    result = associate(obs, turned, camera, PRIOR)
    assert not result.matches and len(result.unmatched) == 4


def test_bhattacharyya_distance_of_equal_histograms_is_zero_and_disjoint_is_one() -> None:
    assert bhattacharyya_distance([1, 2, 3], [2, 4, 6]) < 1e-7
    assert abs(bhattacharyya_distance([1, 0], [0, 1]) - 1.0) < 1e-12


def test_config_gate_is_used(camera: CameraModel) -> None:
    lms, obs = _unlabelled(camera)
    tight = PoseConfig(association=replace(PoseConfig().association, gate_chi2=1e-6))
    far = _prior((0.0, 0.4, 0.0), 0.5, 1.0)
    assert associate(obs, lms, camera, far).matches
    assert not associate(obs, lms, camera, far, tight).matches


def test_low_confidence_observations_are_not_used(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera)
    obs[1] = replace(obs[1], confidence=0.1)
    result = associate(obs, lms, camera, None)
    assert result.unmatched == (1,) and len(result.matches) == 3
    fix = solve_pose(obs, lms, camera, 0)
    assert isinstance(fix, PoseFix) and "B" not in fix.landmark_ids
    assert any("observation 1: confidence" in n for n in fix.notes)
