"""Solver choice and exactness on noise-free views; robustness; bad input gives NoFix."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tracker.camera import CameraModel
from tracker.pose import (
    AltitudeSample,
    AttitudeSample,
    MapLandmark,
    NoFix,
    Observation,
    PoseConfig,
    PoseFix,
    RangeSample,
    solve_pose,
)
from tracker.pose import solve as solve_module
from tracker.pose.simulate import SensorNoise, cast_laser

from .conftest import TRUE_P, TRUE_RPY, assert_exact, see, wall

T_US = 1_000_000
#: an autopilot attitude stated as good to 0.2 deg roll/pitch and 1 deg yaw (the default, a
#: few degrees, is too loose for the consensus to name an 80 px outlier among four centres)
ATT = AttitudeSample(T_US, *TRUE_RPY, float(np.deg2rad(0.2)), float(np.deg2rad(1.0)))


def _fix(result: PoseFix | NoFix) -> PoseFix:
    assert isinstance(result, PoseFix), getattr(result, "reason", "")
    return result


def _centres_only(obs: list[Observation]) -> list[Observation]:
    return [replace(o, corners_px=None) for o in obs]


def _assert_pose(fix: PoseFix) -> None:
    assert_exact(fix, TRUE_P, TRUE_RPY)


def test_single_square_landmark_uses_ippe_square(camera: CameraModel) -> None:
    lms = (MapLandmark("N", (5.0, -0.2, -4.5), 1.2, 1.2, 200.0),)
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US))
    assert fix.solver == "ippe_square" and fix.landmark_ids == ("N",)
    _assert_pose(fix)


def test_far_planar_flip_is_reported_without_attitude_and_resolved_with_it(
    camera: CameraModel,
) -> None:
    lms = wall()[:1]  # 1.2 m sign 20 m away: both IPPE solutions fit within the pixel noise
    result = solve_pose(see(lms, camera), lms, camera, T_US)
    assert isinstance(result, NoFix) and "planar ambiguity" in result.reason
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US, attitude=ATT))
    assert fix.solver == "ippe_square"
    _assert_pose(fix)


def test_single_rectangular_landmark_uses_plain_ippe(camera: CameraModel) -> None:
    lms = wall()[1:2]
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US, attitude=ATT))
    assert fix.solver == "ippe"
    _assert_pose(fix)


def test_several_consistent_landmarks_without_attitude_use_pnp(camera: CameraModel) -> None:
    lms = wall()
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US))
    assert fix.solver == "pnp" and set(fix.landmark_ids) == {"A", "B", "C", "D"}
    _assert_pose(fix)


def test_four_centres_without_attitude_use_pnp(camera: CameraModel) -> None:
    lms = wall()
    fix = _fix(solve_pose(_centres_only(see(lms, camera)), lms, camera, T_US))
    assert fix.solver == "pnp"
    _assert_pose(fix)


def test_two_centres_with_attitude_use_bearing_least_squares(camera: CameraModel) -> None:
    lms = wall()[:2]
    fix = _fix(solve_pose(_centres_only(see(lms, camera)), lms, camera, T_US, attitude=ATT))
    assert fix.solver == "bearing_ls"
    _assert_pose(fix)


def test_one_centre_with_laser_and_attitude_uses_range_bearing(camera: CameraModel) -> None:
    lm = MapLandmark("L", (20.0, 0.0, -5.0), 3.0, 3.0, 180.0)
    p, rpy = np.array([0.5, 0.2, -5.1]), (0.0, 0.01, 0.02)
    d = cast_laser([lm], p, rpy, (1.0, 0.0, 0.0))
    assert d is not None
    laser = RangeSample(T_US, d, (1.0, 0.0, 0.0))
    obs = _centres_only(see((lm,), camera, p, rpy))
    fix = _fix(
        solve_pose(obs, [lm], camera, T_US, attitude=AttitudeSample(T_US, *rpy), laser=laser)
    )
    assert fix.solver == "range_bearing"
    assert_exact(fix, p, rpy)


def test_one_centre_with_altitude_and_attitude_uses_altitude_bearing() -> None:
    cam = CameraModel(mount_rpy_deg=(0.0, -90.0, 0.0))
    lm = MapLandmark("G", (3.0, 2.0, 0.0), 2.0, 2.0, None)
    p, rpy = np.array([1.0, 1.0, -30.0]), (0.01, -0.02, 0.3)
    obs = _centres_only(see((lm,), cam, p, rpy))
    alt = AltitudeSample(T_US, -30.0)
    fix = _fix(solve_pose(obs, [lm], cam, T_US, attitude=AttitudeSample(T_US, *rpy), altitude=alt))
    assert fix.solver == "altitude_bearing"
    assert_exact(fix, p, rpy)


def test_distortion_and_a_down_looking_mount_are_handled() -> None:
    cam = CameraModel(distortion=(-0.2, 0.05, 0.001, -0.001, 0.0), mount_rpy_deg=(0, -90, 0))
    lms = tuple(
        MapLandmark(f"G{i}", (n, e, 0.0), 2.0, 2.0, None)
        for i, (n, e) in enumerate([(-8, -6), (7, -5), (5, 8), (-6, 6)])
    )
    p, rpy = np.array([0.5, 0.5, -25.0]), (0.02, 0.01, 0.4)
    obs = see(lms, cam, p, rpy)
    assert len(obs) == 4
    fix = _fix(solve_pose(obs, lms, cam, T_US))
    assert_exact(fix, p, rpy)


def test_a_wrongly_labelled_landmark_is_dropped_as_an_outlier(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera, noise=SensorNoise(pixel_sigma_px=0.5), seed=3)
    elsewhere = MapLandmark("E", (15.0, 9.0, -2.0), 1.2, 1.2, 180.0)
    obs[2] = replace(obs[2], landmark_id="E")  # the detector named C wrongly
    fix = _fix(solve_pose(obs, (*lms, elsewhere), camera, T_US))
    assert fix.landmark_ids == ("A", "B", "D")
    # RANSAC named the outlier; the rest was refined from RANSAC's pose
    assert any("dropped landmark 'E': RANSAC outlier" in n for n in fix.notes)
    assert fix.solver == "pnp_ransac"
    assert np.linalg.norm(np.asarray(fix.position_ned_m) - TRUE_P) < 0.1


def test_when_ransac_finds_no_pose_sqpnp_through_every_point_decides(
    camera: CameraModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    # AP3P RANSAC can miss a clean view of few, coplanar points (4 ground centres, 1 in 20)
    monkeypatch.setattr(solve_module, "pnp_ransac", lambda *a, **k: None)
    lms = wall()
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US))
    assert fix.solver == "pnp" and set(fix.landmark_ids) == {"A", "B", "C", "D"}
    _assert_pose(fix)


def test_a_poor_ransac_refit_does_not_drop_a_landmark_sqpnp_fits(
    camera: CameraModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    # OpenCV refits RANSAC's pose with EPnP, poor on coplanar points: a noisy point outside
    # its mask and a refit off by metres must not name a landmark when every point fits SQPnP
    real = solve_module.pnp_ransac

    def poor_refit(*args: Any, **kwargs: Any) -> Any:
        out = real(*args, **kwargs)
        assert out is not None
        cand, mask = out
        mask = mask.copy()
        mask[0] = False
        return replace(cand, x0=cand.x0 + np.array([0.0, 3.0, 0.0, 0.0, 0.0, 0.0])), mask

    monkeypatch.setattr(solve_module, "pnp_ransac", poor_refit)
    lms = wall()
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US))
    assert fix.solver == "pnp" and set(fix.landmark_ids) == {"A", "B", "C", "D"}
    assert not any("dropped" in n for n in fix.notes)
    _assert_pose(fix)


def test_with_one_of_two_landmarks_mislabelled_the_attitude_solver_drops_it(
    camera: CameraModel,
) -> None:
    lms = wall()
    obs = _centres_only(see(lms, camera))
    obs[3] = replace(obs[3], centre_px=(obs[3].centre_px[0] - 80.0, obs[3].centre_px[1]))
    fix = _fix(solve_pose(obs, lms, camera, T_US, attitude=ATT))
    assert fix.landmark_ids == ("A", "B", "C")
    assert any("'D'" in n for n in fix.notes)


@pytest.mark.parametrize(
    ("field", "value", "needle"),
    [
        ("centre_px", (float("nan"), 10.0), "centre_px"),
        ("box_wh_px", (10.0, float("inf")), "box_wh_px"),
        ("confidence", float("nan"), "confidence"),
        ("centre_px", (1e9, 10.0), "outside the image"),
    ],
)
def test_nan_in_an_observation_gives_no_fix_with_the_reason(
    camera: CameraModel, field: str, value: object, needle: str
) -> None:
    lms = wall()
    obs = see(lms, camera)
    kwargs: dict[str, Any] = {field: value}
    obs[2] = replace(obs[2], **kwargs)
    result = solve_pose(obs, lms, camera, T_US)
    assert isinstance(result, NoFix)
    assert "observation 2" in result.reason and needle in result.reason


def test_nan_in_a_corner_gives_no_fix(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera)
    corners = list(obs[0].corners_px or ())
    corners[1] = (float("nan"), 3.0)
    obs[0] = replace(obs[0], corners_px=tuple(corners))
    result = solve_pose(obs, lms, camera, T_US)
    assert isinstance(result, NoFix) and "corners_px" in result.reason


def test_all_points_on_one_pixel_is_degenerate(camera: CameraModel) -> None:
    lms = wall()
    obs = [
        replace(o, centre_px=(300.0, 200.0), corners_px=((300.0, 200.0),) * 4)
        for o in see(lms, camera)
    ]
    result = solve_pose(obs, lms, camera, T_US)
    assert isinstance(result, NoFix) and "degenerate" in result.reason


def test_collinear_landmarks_without_attitude_give_no_fix(camera: CameraModel) -> None:
    lms = tuple(
        MapLandmark(f"L{i}", (20.0 + i, -6.0 + 4 * i, -4.0), 1.0, 1.0, 180.0) for i in range(4)
    )
    obs = _centres_only(see(lms, camera, np.array([0.0, 0.0, -2.0]), (0.0, 0.0, 0.0)))
    assert len(obs) == 4
    result = solve_pose(obs, lms, camera, T_US)
    assert isinstance(result, NoFix) and "collinear" in result.reason


def test_a_landmark_behind_the_camera_gives_no_fix(camera: CameraModel) -> None:
    lm = MapLandmark("G", (0.0, 0.0, 0.0), 2.0, 2.0, None)
    # camera looks forward and up (pitch +30 deg) but the landmark lies below on the ground
    obs = [Observation((320.0, 100.0), (20.0, 20.0), landmark_id="G")]
    att = AttitudeSample(T_US, 0.0, np.deg2rad(30.0), 0.0)
    result = solve_pose(obs, [lm], camera, T_US, attitude=att, altitude=AltitudeSample(T_US, -10.0))
    assert isinstance(result, NoFix) and "behind" in result.reason


def test_one_centre_and_nothing_else_is_unobservable(camera: CameraModel) -> None:
    lms = wall()[:1]
    obs = _centres_only(see(lms, camera))
    no_size = PoseConfig(box_size_sigma_rel=0.0)
    result = solve_pose(obs, lms, camera, T_US, attitude=ATT, config=no_size)
    assert isinstance(result, NoFix) and "unobservable" in result.reason
    result = solve_pose(obs, lms, camera, T_US)
    assert isinstance(result, NoFix) and "unobservable" in result.reason


def test_one_centre_with_attitude_gives_a_weak_fix_from_its_box_size() -> None:
    """The box of a plate seen head-on has its size: f * size / pixels is the distance,
    trusted to a fifth; the fix says so (sigma along the line of sight ~ 20 % of it)."""
    cam = CameraModel()
    lm = MapLandmark("S", (20.0, 0.0, -5.0), 2.0, 1.5, 180.0)
    p, rpy = np.array([0.0, 0.0, -5.0]), (0.0, 0.0, 0.0)
    obs = _centres_only(see((lm,), cam, p, rpy))
    fix = _fix(solve_pose(obs, [lm], cam, T_US, attitude=AttitudeSample(T_US, *rpy)))
    assert fix.solver == "size_bearing"
    sigma = np.sqrt(np.diag(fix.covariance))
    assert sigma[0] == pytest.approx(0.2 * 20.0, rel=0.05)  # along the line of sight (north)
    assert abs(fix.position_ned_m[0] - p[0]) < 0.05 * sigma[0]  # exact box: no error
    assert abs(fix.position_ned_m[1] - p[1]) < 0.5  # across: the attitude's 5 deg propagated
    assert sigma[1] == pytest.approx(20.0 * np.deg2rad(5.0), rel=0.1)


def test_a_stale_attitude_is_ignored(camera: CameraModel) -> None:
    lms = wall()[:2]
    obs = _centres_only(see(lms, camera))
    stale = replace(ATT, time_us=T_US - 500_000)
    result = solve_pose(obs, lms, camera, T_US, attitude=stale)
    assert isinstance(result, NoFix)
    assert any("attitude sample ignored" in n for n in result.notes)
    assert isinstance(solve_pose(obs, lms, camera, T_US, attitude=ATT), PoseFix)


def test_no_identified_landmark_gives_no_fix(camera: CameraModel) -> None:
    result = solve_pose([], wall(), camera, T_US)
    assert isinstance(result, NoFix) and "no identified landmark" in result.reason


def test_covariance_is_symmetric_positive_definite_and_ordered(camera: CameraModel) -> None:
    lms = wall()
    fix = _fix(solve_pose(see(lms, camera), lms, camera, T_US))
    c = fix.covariance
    assert c.shape == (6, 6)
    np.testing.assert_allclose(c, c.T)
    assert np.all(np.linalg.eigvalsh(c) > 0)
    # looking north at a wall: depth (north) is known worse than... the angles are radians
    assert np.all(np.sqrt(np.diag(c)[3:]) < 0.1)
    assert 1 <= fix.quality <= 100


def test_distance_sensor_orientations_map_to_body_axes() -> None:
    from tracker.pose import laser_axis_from_mav_orientation as axis

    assert axis(0) == (1.0, 0.0, 0.0)
    assert axis(2) == (0.0, 1.0, 0.0)  # YAW_90: right
    assert axis(25) == (0.0, 0.0, 1.0)  # PITCH_270: down
    assert axis(24) == (0.0, 0.0, -1.0)
    with pytest.raises(ValueError, match="orientation"):
        axis(100)


def test_downward_laser_over_a_flat_landmark_fixes_height(camera: CameraModel) -> None:
    cam = CameraModel(mount_rpy_deg=(0.0, -90.0, 0.0))
    lm = MapLandmark("G", (0.0, 0.0, 0.0), 3.0, 3.0, None)
    p, rpy = np.array([0.3, -0.2, -12.0]), (0.01, 0.02, 1.0)
    d = cast_laser([lm], p, rpy, (0.0, 0.0, 1.0))
    assert d is not None
    obs = _centres_only(see((lm,), cam, p, rpy))
    fix = _fix(
        solve_pose(
            obs,
            [lm],
            cam,
            T_US,
            attitude=AttitudeSample(T_US, *rpy),
            laser=RangeSample(T_US, d, (0.0, 0.0, 1.0)),
        )
    )
    assert fix.solver == "range_bearing"
    assert_exact(fix, p, rpy)


def test_with_attitude_a_gross_misassociation_is_found_by_landmark_consensus(
    camera: CameraModel,
) -> None:
    lms = wall()
    obs = _centres_only(see(lms, camera, noise=SensorNoise(), seed=5))
    elsewhere = MapLandmark("E", (30.0, 12.0, -1.0), 1.2, 1.2, 180.0)
    obs[2] = replace(obs[2], landmark_id="E")  # C seen, but named E (far to the right)
    fix = _fix(solve_pose(obs, (*lms, elsewhere), camera, T_US, attitude=ATT))
    assert fix.landmark_ids == ("A", "B", "D")
    assert any("'E': disagrees with the other landmarks' consensus" in n for n in fix.notes)
    assert np.linalg.norm(np.asarray(fix.position_ned_m) - TRUE_P) < 4 * max(fix.position_sigma_m)


def test_a_landmark_whose_back_the_camera_would_see_is_dropped(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera)
    # the map says A faces north (away from the camera): it cannot be what was seen
    turned = (replace(lms[0], facing_deg=0.0), *lms[1:])
    fix = _fix(solve_pose(_centres_only(obs), turned, camera, T_US, attitude=ATT))
    assert "A" not in fix.landmark_ids
    assert any("'A': the camera is behind its face" in n for n in fix.notes)


def test_nan_side_samples_are_ignored_not_propagated(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera)
    bad_att = replace(ATT, yaw_rad=float("nan"))
    bad_alt = AltitudeSample(T_US, float("inf"))
    bad_laser = RangeSample(T_US, float("nan"))
    fix = _fix(
        solve_pose(obs, lms, camera, T_US, attitude=bad_att, altitude=bad_alt, laser=bad_laser)
    )
    assert fix.solver == "pnp"  # solved as if no attitude had come
    for name in ("attitude", "altitude", "laser"):
        assert any(f"{name} sample ignored: not finite" in n for n in fix.notes)
    assert np.all(np.isfinite(fix.covariance))


def test_three_landmarks_with_one_misnamed_give_no_fix_rather_than_a_guess(
    camera: CameraModel,
) -> None:
    lms = wall()[:3]
    obs = see(lms, camera)
    elsewhere = MapLandmark("E", (15.0, 9.0, -2.0), 1.2, 1.2, 180.0)
    obs[2] = replace(obs[2], landmark_id="E")
    for att in (None, ATT):
        result = solve_pose(obs, (*lms, elsewhere), camera, T_US, attitude=att)
        assert isinstance(result, NoFix)
        assert "disagree" in result.reason or "no three landmarks agree" in result.reason


def test_two_detections_claiming_one_landmark_are_both_left_out(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera)
    obs[3] = replace(obs[3], landmark_id="A")  # D's detection also named A
    fix = _fix(solve_pose(obs, lms, camera, T_US))
    assert fix.landmark_ids == ("B", "C")
    assert any("'A' claimed by observations [0, 3]" in n for n in fix.notes)


def test_a_single_landmark_left_after_a_double_claim_gives_no_fix(camera: CameraModel) -> None:
    """Two detections claim A, a third is named B: A is left out, and B alone could be the
    misnamed one with nothing to check it against -- no fix, with the reason."""
    lms = wall()
    obs = see(lms, camera)
    two_a_one_b = [obs[0], replace(obs[2], landmark_id="A"), obs[1]]
    result = solve_pose(two_a_one_b, lms, camera, T_US)
    assert isinstance(result, NoFix)
    assert "claimed twice" in result.reason
    assert any("'A' claimed by observations [0, 1]" in n for n in result.notes)
    alone = solve_pose([obs[1]], lms, camera, T_US)  # B alone, no conflict: a fix
    assert isinstance(alone, PoseFix)


@pytest.mark.parametrize("att", [None, ATT])
def test_of_three_landmarks_the_one_that_does_not_fit_is_named(
    camera: CameraModel, att: AttitudeSample | None
) -> None:
    """Three landmarks, one plate's top edge 8 px off (an outline aligned wrong): no fix (too
    few to outvote it), but the one that does not fit is named, so that the tracks can count
    it (the coupled hover's 7 s without a fix in CI, 2026-12-03). Of two, none is named:
    either may be the wrong one."""
    lms = wall()[:3]
    obs = [replace(o, corner_sigma_px=0.5) for o in see(lms, camera)]
    corners = np.array(obs[1].corners_px)
    corners[:2, 0] += 8.0
    obs[1] = replace(obs[1], corners_px=tuple((float(u), float(v)) for u, v in corners))
    result = solve_pose(obs, lms, camera, T_US, attitude=att)
    assert isinstance(result, NoFix) and "disagree" in result.reason, result
    assert result.outlier == "B"
    pair = solve_pose(obs[:2], lms[:2], camera, T_US, attitude=att)
    assert not isinstance(pair, NoFix) or pair.outlier is None
