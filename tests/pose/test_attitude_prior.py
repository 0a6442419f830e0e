"""The autopilot's attitude is a prior that cannot pull an observable fix away (issue 19).

The autopilot's attitude is itself estimated from our fixes: a fix that moves because the
attitude moved, with the landmarks still, feeds the error back.  Whenever the landmarks
alone fix the pose, the fix must stay where they put it, whatever the attitude's error.
"""

from __future__ import annotations

import numpy as np
import pytest

from tracker.camera import CameraModel
from tracker.pose import AttitudeSample, MapLandmark, NoFix, Observation, PoseFix, solve_pose
from tracker.pose.simulate import SensorNoise

from .conftest import TRUE_P, TRUE_RPY, see, wall

NOISE = SensorNoise(pixel_sigma_px=0.3)  # the perception's corner noise (docs/pose.md)


def _fix(result: PoseFix | NoFix) -> PoseFix:
    assert isinstance(result, PoseFix), getattr(result, "reason", "")
    return result


def _wrong(deg: float, axis: int) -> tuple[float, float, float]:
    rpy = list(TRUE_RPY)
    rpy[axis] += float(np.deg2rad(deg))
    return rpy[0], rpy[1], rpy[2]


def _mahalanobis2(fix: PoseFix, ref: PoseFix) -> float:
    d = np.asarray(fix.position_ned_m) - np.asarray(ref.position_ned_m)
    return float(d @ np.linalg.solve(ref.covariance[:3, :3], d))


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["roll", "pitch", "yaw"])
@pytest.mark.parametrize("deg", [5.0, 10.0, 20.0])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_wrong_attitude_does_not_move_an_observable_fix(
    camera: CameraModel, deg: float, axis: int, seed: int
) -> None:
    """Four plates with corners: the fix with an attitude 5-20 deg wrong (stated with the
    default sigma) stays within one sigma of where the landmarks alone put it.

    Within the gate the prior is fused, and fusion moves the fix by at most the gate's
    chi-square weighted by the landmarks' share of the uncertainty (here 0.01-0.2 sigma^2;
    today's 0.2 deg prior moved it 220-1800 sigma^2 or lost the fix)."""
    lms = wall()
    obs = see(lms, camera, noise=NOISE, seed=seed)
    alone = _fix(solve_pose(obs, lms, camera, 0))
    fix = _fix(solve_pose(obs, lms, camera, 0, attitude=AttitudeSample(0, *_wrong(deg, axis))))
    assert set(fix.landmark_ids) == set(alone.landmark_ids)
    assert _mahalanobis2(fix, alone) < 1.0, (fix.position_ned_m, alone.position_ned_m)
    err = np.linalg.norm(np.asarray(fix.position_ned_m) - TRUE_P)
    assert err < 3.0 * np.sqrt(np.trace(alone.covariance[:3, :3]))


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["roll", "pitch", "yaw"])
def test_a_confidently_wrong_attitude_is_rejected_with_a_note(
    camera: CameraModel, axis: int
) -> None:
    """An autopilot that states 0.2 deg / 1 deg and is 5 deg off: the prior is dropped for
    this fix, which is the landmarks' own, and the fix says so."""
    lms = wall()
    obs = see(lms, camera, noise=NOISE, seed=4)
    alone = _fix(solve_pose(obs, lms, camera, 0))
    att = AttitudeSample(0, *_wrong(5.0, axis), float(np.deg2rad(0.2)), float(np.deg2rad(1.0)))
    fix = _fix(solve_pose(obs, lms, camera, 0, attitude=att))
    assert fix.attitude_prior == "rejected"
    assert any(n.startswith("attitude prior rejected: ") for n in fix.notes)
    np.testing.assert_allclose(fix.position_ned_m, alone.position_ned_m)
    np.testing.assert_allclose(fix.covariance, alone.covariance)


def test_a_consistent_attitude_is_used(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera, noise=NOISE, seed=5)
    fix = _fix(solve_pose(obs, lms, camera, 0, attitude=AttitudeSample(0, *TRUE_RPY)))
    assert fix.attitude_prior == "used"
    assert not any("rejected" in n for n in fix.notes)
    alone = _fix(solve_pose(obs, lms, camera, 0))
    assert alone.attitude_prior == "none"
    # the prior adds information: the fix is not less certain than the landmarks' alone
    assert np.trace(fix.covariance[:3, :3]) <= np.trace(alone.covariance[:3, :3])


def test_without_an_observable_view_the_attitude_is_used_and_its_sigma_propagated(
    camera: CameraModel,
) -> None:
    """Two landmark centres cannot fix the pose alone: nothing to check the attitude
    against, so it is used, and a looser attitude makes a less certain fix."""
    lms = wall()[:2]
    obs = [o for o in see(lms, camera) if o is not None]
    obs = [type(o)(o.centre_px, o.box_wh_px, landmark_id=o.landmark_id) for o in obs]
    loose = _fix(solve_pose(obs, lms, camera, 0, attitude=AttitudeSample(0, *TRUE_RPY)))
    tight = _fix(solve_pose(obs, lms, camera, 0, attitude=AttitudeSample(
        0, *TRUE_RPY, float(np.deg2rad(0.2)), float(np.deg2rad(1.0)))))
    assert loose.attitude_prior == tight.attitude_prior == "used"
    assert np.trace(loose.covariance[:3, :3]) > 4.0 * np.trace(tight.covariance[:3, :3])


def _one_plate(camera: CameraModel, seed: int
               ) -> tuple[list[Observation], tuple[MapLandmark, ...]]:
    """Plate A alone, 20 m off, as the perception's corners give it."""
    lms = wall()[:1]
    return see(lms, camera, noise=NOISE, seed=seed), lms


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["roll", "pitch", "yaw"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_fix_does_not_follow_an_attitude_step_within_its_sigma(
    camera: CameraModel, axis: int, seed: int
) -> None:
    """The issue's rule: landmarks still, the attitude stepped by its own stated sigma
    (2.5 deg roll/pitch, 5 deg yaw): the one-plate fix, whose rotation its corners fix only
    weakly, moves by no more than its own covariance allows (Mahalanobis distance of the
    move under 1), or the prior is refused."""
    obs, lms = _one_plate(camera, seed)
    sig = AttitudeSample(0, *TRUE_RPY)
    step = (sig.roll_pitch_sigma_rad, sig.roll_pitch_sigma_rad, sig.yaw_sigma_rad)[axis]
    before = _fix(solve_pose(obs, lms, camera, 0, attitude=sig))
    after = _fix(solve_pose(obs, lms, camera, 0, attitude=AttitudeSample(
        0, *_wrong(float(np.rad2deg(step)), axis))))
    moved = np.asarray(after.position_ned_m) - np.asarray(before.position_ned_m)
    m2 = float(moved @ np.linalg.solve(after.covariance[:3, :3], moved))
    print(f"{('roll', 'pitch', 'yaw')[axis]} +{np.rad2deg(step):.1f} deg: moved "
          f"{np.linalg.norm(moved):.3f} m, {np.sqrt(m2):.2f} sigma, prior "
          f"{after.attitude_prior}")
    assert after.attitude_prior == "rejected" or m2 < 1.0
