"""Plates cut by the image's edge give their measured corners, and only those (issue 19).

On the square's leg to (6, 6) the only landmarks in view are cut by the image's edge; the
corners outside are extrapolations of the alignment (pixels off), the ones inside are as
good as any.  ``Observation.corners_measured`` says which are which; the solver uses the
measured ones as points (and no box size: a cut box is not the plate's size).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tracker.camera import CameraModel
from tracker.pose import AltitudeSample, AttitudeSample, NoFix, Observation, PoseFix, solve_pose
from tracker.pose.simulate import SensorNoise

from .conftest import TRUE_P, TRUE_RPY, see, wall

PIXEL_SIGMA = 0.5
NOISE = SensorNoise(pixel_sigma_px=PIXEL_SIGMA)
CHI2_3_95 = 7.815  # chi-square, 3 DOF, 95 %
RP_SIGMA, YAW_SIGMA = float(np.deg2rad(1.0)), float(np.deg2rad(3.0))  # the fake's EKF's


def _cut(obs: Observation, measured: tuple[bool, bool, bool, bool],
         garbage_px: float = 0.0) -> Observation:
    """``obs`` as a plate cut by the edge: the unmeasured corners moved by ``garbage_px``
    (an extrapolation), the sigma stated."""
    assert obs.corners_px is not None
    corners = tuple((u + (0.0 if m else garbage_px), v - (0.0 if m else garbage_px))
                    for (u, v), m in zip(obs.corners_px, measured, strict=True))
    return replace(obs, corners_px=corners, corners_measured=measured,
                   corner_sigma_px=PIXEL_SIGMA)


def _two_cut(camera: CameraModel, seed: int, garbage_px: float = 0.0) -> list[Observation]:
    lms = wall()
    obs = {o.landmark_id: o for o in see(lms, camera, noise=NOISE, seed=seed)}
    return [_cut(obs["A"], (False, True, False, False), garbage_px),
            _cut(obs["C"], (True, False, False, True), garbage_px)]


def _priors(rng: np.random.Generator) -> tuple[AttitudeSample, AltitudeSample]:
    rpy = np.asarray(TRUE_RPY) + rng.normal(0.0, 1.0, 3) * (RP_SIGMA, RP_SIGMA, YAW_SIGMA)
    att = AttitudeSample(0, float(rpy[0]), float(rpy[1]), float(rpy[2]), RP_SIGMA, YAW_SIGMA)
    return att, AltitudeSample(0, float(TRUE_P[2] + rng.normal(0.0, 0.3)), 0.3)


def _fix(result: PoseFix | NoFix) -> PoseFix:
    assert isinstance(result, PoseFix), getattr(result, "reason", "")
    return result


def test_the_corners_outside_the_image_are_not_used(camera: CameraModel) -> None:
    """Moving the unmeasured corners by 40 px does not move the fix (it would without
    ``corners_measured``: the old solver took all four)."""
    rng = np.random.default_rng(0)
    att, alt = _priors(rng)
    clean = _fix(solve_pose(_two_cut(camera, 1), wall(), camera, 0, attitude=att,
                            altitude=alt))
    moved = _fix(solve_pose(_two_cut(camera, 1, 40.0), wall(), camera, 0, attitude=att,
                            altitude=alt))
    np.testing.assert_allclose(moved.position_ned_m, clean.position_ned_m, atol=1e-9)
    assert clean.solver == "bearing_ls"


def test_three_measured_corners_of_two_cut_plates_give_honest_fixes(
        camera: CameraModel) -> None:
    """With the attitude and height priors (the fake EKF's sigmas), 200 noisy frames: a
    fix every time, and its position NEES inside the 95 % bound for at least 90 %."""
    rng = np.random.default_rng(7)
    nees = []
    for seed in range(200):
        att, alt = _priors(rng)
        fix = _fix(solve_pose(_two_cut(camera, seed), wall(), camera, 0, attitude=att,
                              altitude=alt))
        d = np.asarray(fix.position_ned_m) - TRUE_P
        nees.append(float(d @ np.linalg.solve(fix.covariance[:3, :3], d)))
    inside = float(np.mean(np.asarray(nees) <= CHI2_3_95))
    print(f"cut plates: NEES median {np.median(nees):.2f}, inside 95 % {inside:.2f}")
    assert inside >= 0.9


def test_one_cut_plate_uses_its_corner_and_the_height_not_its_box(
        camera: CameraModel) -> None:
    """One corner of one plate, attitude and height: an altitude-bearing fix (a cut box's
    size would put the plate too far)."""
    obs = {o.landmark_id: o for o in see(wall(), camera)}
    half = replace(obs["A"], box_wh_px=(obs["A"].box_wh_px[0] / 3, obs["A"].box_wh_px[1]))
    cut = _cut(half, (True, False, False, False))
    fix = _fix(solve_pose([cut], wall(), camera, 0, attitude=AttitudeSample(0, *TRUE_RPY),
                          altitude=AltitudeSample(0, float(TRUE_P[2]), 0.05)))
    assert fix.solver == "altitude_bearing"
    d = np.asarray(fix.position_ned_m) - TRUE_P
    assert float(d @ np.linalg.solve(fix.covariance[:3, :3], d)) < 1e-6


@pytest.mark.parametrize("measured", [(False, False, False, False), (True, True, True)])
def test_corners_measured_is_checked(camera: CameraModel,
                                     measured: tuple[bool, ...]) -> None:
    obs = see(wall(), camera)[0]
    bad = replace(obs, corners_measured=measured)  # type: ignore[arg-type]
    out = solve_pose([bad], wall(), camera, 0)
    assert isinstance(out, NoFix)
    assert "corners_measured" in out.reason


def _extrapolated(obs: Observation, measured: tuple[bool, bool, bool, bool],
                  sigma_out: float, rng: np.random.Generator) -> Observation:
    """``obs`` cut by the edge, its unmeasured corners extrapolated with ``sigma_out`` px of
    error and stated so (``Observation.extrapolated_sigma_px``)."""
    assert obs.corners_px is not None
    corners = tuple((u, v) if m else tuple(np.add((u, v), rng.normal(0.0, sigma_out, 2)))
                    for (u, v), m in zip(obs.corners_px, measured, strict=True))
    return replace(obs, corners_px=corners, corners_measured=measured,
                   corner_sigma_px=PIXEL_SIGMA, extrapolated_sigma_px=sigma_out)


def test_extrapolated_corners_are_weak_points_that_hold_the_fix(camera: CameraModel) -> None:
    """One measured corner of one plate, the other three extrapolated with an error of 5 %
    of the plate's size and stated so: over 200 noisy frames (the fake EKF's attitude and
    height sigmas) the fix's NEES is inside the 95 % bound for at least 90 %, and its
    horizontal 1-sigma is under a third of the one-corner fix's (the corner's bearing alone
    leaves the range to the attitude's depression angle)."""
    rng = np.random.default_rng(3)
    measured = (True, False, False, False)
    nees, ratio = [], []
    for seed in range(200):
        att, alt = _priors(rng)
        obs = see(wall(), camera, noise=NOISE, seed=seed)[0]
        assert obs.corners_px is not None
        (a, b), (c, d) = np.subtract(obs.corners_px[2], obs.corners_px[0]), \
            np.subtract(obs.corners_px[3], obs.corners_px[1])
        size = float(np.sqrt(abs(a * d - b * c) / 2))  # the square root of its area
        extrapolated = _extrapolated(obs, measured, 0.05 * size, rng)
        lone = solve_pose([_cut(obs, measured)], wall(), camera, 0, attitude=att, altitude=alt)
        if isinstance(lone, NoFix):  # the attitude's noise put the corner above the horizon
            continue  # the start both solves share (bearing_least_squares) is behind: none
        weak = _fix(solve_pose([extrapolated], wall(), camera, 0, attitude=att, altitude=alt))
        d = np.asarray(weak.position_ned_m) - TRUE_P
        nees.append(float(d @ np.linalg.solve(weak.covariance[:3, :3], d)))
        ratio.append(float(np.sqrt(np.max(np.linalg.eigvalsh(weak.covariance[:2, :2]))
                                   / np.max(np.linalg.eigvalsh(lone.covariance[:2, :2])))))
    inside = float(np.mean(np.asarray(nees) <= CHI2_3_95))
    print(f"extrapolated corners: {len(nees)} fixes, NEES median {np.median(nees):.2f}, "
          f"inside 95 % {inside:.2f}, "
          f"horizontal sigma against one corner's median {np.median(ratio):.3f}")
    assert len(nees) >= 100  # 117: the corner is near the horizon in this scene
    assert inside >= 0.9
    assert float(np.median(ratio)) < 1 / 3


def test_extrapolated_sigma_needs_corners_measured(camera: CameraModel) -> None:
    obs = see(wall(), camera)[0]
    out = solve_pose([replace(obs, extrapolated_sigma_px=3.0)], wall(), camera, 0)
    assert isinstance(out, NoFix)
    assert "extrapolated_sigma_px" in out.reason
