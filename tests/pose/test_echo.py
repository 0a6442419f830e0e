"""``PoseFix.echo_covariance``: the part of a fix's covariance that the autopilot's own
attitude and height carry (issue 19).

A fix resting on the autopilot's estimate repeats that estimate's error in every frame while
it lasts; companion.fixgate states such a stream as correlated.  What is checked here is the
split itself: with exact pixels, every bit of the fixes' spread comes from the priors' draws,
and it is what ``echo_covariance`` says.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tracker.camera import CameraModel
from tracker.pose import AltitudeSample, AttitudeSample, NoFix, Observation, PoseFix, solve_pose

from .conftest import TRUE_P, TRUE_RPY, see, wall

#: the fake EKF's attitude sigmas and a height sigma small enough for the first-order
#: picture to hold (the corner is 2 m below the camera, 17 m ahead)
RP_SIGMA, YAW_SIGMA, ALT_SIGMA = float(np.deg2rad(1.0)), float(np.deg2rad(3.0)), 0.2


def _one_corner(camera: CameraModel) -> list[Observation]:
    """Landmark C alone, cut by the edge: one measured corner (the (6, 6) hover's view)."""
    obs = {o.landmark_id: o for o in see(wall(), camera)}["C"]
    return [replace(obs, corners_measured=(False, False, False, True), corner_sigma_px=0.3)]


def _drawn(rng: np.random.Generator) -> tuple[AttitudeSample, AltitudeSample]:
    rpy = np.asarray(TRUE_RPY) + rng.normal(0.0, 1.0, 3) * (RP_SIGMA, RP_SIGMA, YAW_SIGMA)
    att = AttitudeSample(0, float(rpy[0]), float(rpy[1]), float(rpy[2]), RP_SIGMA, YAW_SIGMA)
    return att, AltitudeSample(0, float(TRUE_P[2] + rng.normal(0.0, ALT_SIGMA)), ALT_SIGMA)


def _fix(result: PoseFix | NoFix) -> PoseFix:
    assert isinstance(result, PoseFix), getattr(result, "reason", "")
    return result


def test_exact_pixels_spread_as_the_autopilots_part_says(camera: CameraModel) -> None:
    """One measured corner, the attitude and height drawn from their stated sigmas, pixels
    exact: the fixes' spread is the autopilot's part (within sampling), and that part is
    nearly all of the stated covariance (the corner gives a bearing, the height a range)."""
    rng = np.random.default_rng(3)
    fixes = [_fix(solve_pose(_one_corner(camera), wall(), camera, 0,
                             attitude=a, altitude=h)) for a, h in (_drawn(rng) for _ in range(400))]
    assert {f.solver for f in fixes} == {"altitude_bearing"}
    spread = np.cov(np.array([f.position_ned_m for f in fixes]).T)
    echo = np.mean([np.asarray(f.echo_covariance)[:3, :3] for f in fixes], axis=0)
    stated = np.mean([np.asarray(f.covariance)[:3, :3] for f in fixes], axis=0)
    assert 0.8 < np.trace(spread) / np.trace(echo) < 1.25, (np.trace(spread), np.trace(echo))
    assert np.trace(echo) > 0.9 * np.trace(stated)


def test_four_whole_plates_carry_little_of_the_autopilot(camera: CameraModel) -> None:
    """Four plates' corners fix the pose themselves: the priors' part is a small share."""
    obs = see(wall(), camera)
    assert len(obs) == 4
    att, alt = _drawn(np.random.default_rng(4))
    fix = _fix(solve_pose(obs, wall(), camera, 0, attitude=att, altitude=alt))
    assert fix.echo_covariance is not None
    share = np.trace(fix.echo_covariance[:3, :3]) / np.trace(fix.covariance[:3, :3])
    assert share < 0.15, share


def test_without_the_autopilots_estimate_there_is_no_such_part(camera: CameraModel) -> None:
    obs = [o for o in see(wall(), camera) if o.landmark_id in ("A", "C")]
    assert _fix(solve_pose(obs, wall(), camera, 0)).echo_covariance is None
