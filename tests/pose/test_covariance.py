"""The covariance is honest: Monte Carlo NEES matches chi-square(3); garbage never gives NaN."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from tracker.camera import CameraModel
from tracker.pose import AttitudeSample, NoFix, Observation, PoseConfig, PoseFix, solve_pose
from tracker.pose.scenarios import NEES_HIGH_3DOF, NEES_LOW_3DOF
from tracker.pose.simulate import SensorNoise

from .conftest import TRUE_P, TRUE_RPY, see, wall

NOISE = SensorNoise(pixel_sigma_px=1.0, centre_sigma_px=1.0)


def _nees_run(camera: CameraModel, use_attitude: bool, corners: bool, trials: int) -> np.ndarray:
    rng = np.random.default_rng(7)
    cfg = PoseConfig(pixel_sigma_px=1.0, centre_sigma_px=1e-3)
    lms = wall()
    out = []
    for i in range(trials):
        obs = see(lms, camera, noise=NOISE, seed=1000 + i)
        if not corners:
            obs = [replace(o, corners_px=None) for o in obs]
        att = None
        if use_attitude:
            noisy = np.asarray(TRUE_RPY) + rng.normal(0, 1, 3) * np.deg2rad([0.1, 0.1, 1.0])
            r, p, y = (float(v) for v in noisy)
            att = AttitudeSample(0, r, p, y, float(np.deg2rad(0.1)), float(np.deg2rad(1.0)))
        fix = solve_pose(obs, lms, camera, 0, attitude=att, config=cfg)
        assert isinstance(fix, PoseFix), getattr(fix, "reason", "")
        e = np.asarray(fix.position_ned_m) - TRUE_P
        out.append(float(e @ np.linalg.solve(fix.covariance[:3, :3], e)))
    return np.array(out)


def test_pnp_position_nees_is_chi_square_3(camera: CameraModel) -> None:
    nees = _nees_run(camera, use_attitude=False, corners=True, trials=150)
    inside = np.mean((nees >= NEES_LOW_3DOF) & (nees <= NEES_HIGH_3DOF))
    assert 2.4 < nees.mean() < 3.6  # E[chi2(3)] = 3; 150 trials give +-0.4 at 3 sigma
    assert inside >= 0.9


def test_bearing_ls_position_nees_is_chi_square_3(camera: CameraModel) -> None:
    nees = _nees_run(camera, use_attitude=True, corners=False, trials=150)
    inside = np.mean((nees >= NEES_LOW_3DOF) & (nees <= NEES_HIGH_3DOF))
    assert 2.4 < nees.mean() < 3.6
    assert inside >= 0.9


def test_more_pixel_noise_gives_a_larger_covariance(camera: CameraModel) -> None:
    lms = wall()
    obs = see(lms, camera)
    small = solve_pose(obs, lms, camera, 0, config=PoseConfig(pixel_sigma_px=0.5))
    large = solve_pose(obs, lms, camera, 0, config=PoseConfig(pixel_sigma_px=2.0))
    assert isinstance(small, PoseFix) and isinstance(large, PoseFix)
    np.testing.assert_allclose(large.covariance, 16.0 * small.covariance, rtol=1e-6)
    assert large.quality <= small.quality


_num = st.floats(allow_nan=True, allow_infinity=True, width=64) | st.floats(-2000, 2000)
_pair = st.tuples(_num, _num)


@settings(max_examples=60, deadline=None)
@given(
    centres=st.lists(_pair, min_size=0, max_size=5),
    boxes=st.lists(st.tuples(st.floats(0, 500), st.floats(0, 500)), min_size=5, max_size=5),
    corners=st.lists(st.none() | st.tuples(_pair, _pair, _pair, _pair), min_size=5, max_size=5),
    use_attitude=st.booleans(),
)
def test_any_input_gives_a_finite_fix_or_a_reason(
    centres: list[tuple[float, float]],
    boxes: list[tuple[float, float]],
    corners: list[tuple[tuple[float, float], ...] | None],
    use_attitude: bool,
) -> None:
    camera = CameraModel()
    lms = wall()
    ids = [lm.landmark_id for lm in lms]
    obs = [
        Observation(c, boxes[i], 0.9, ids[i % len(ids)], corners_px=corners[i])
        for i, c in enumerate(centres)
    ]
    att = AttitudeSample(0, *TRUE_RPY) if use_attitude else None
    result = solve_pose(obs, lms, camera, 0, attitude=att)
    if isinstance(result, NoFix):
        assert result.reason
        return
    values = np.concatenate(
        [result.position_ned_m, result.attitude_rpy_rad, result.covariance.ravel()]
    )
    assert np.all(np.isfinite(values))
    assert np.all(np.linalg.eigvalsh(result.covariance) > 0)
