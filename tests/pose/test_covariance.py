"""The covariance is honest: Monte Carlo NEES matches chi-square(3); garbage never gives NaN."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracker.camera import CameraModel
from tracker.pose import AttitudeSample, NoFix, Observation, PoseConfig, PoseFix, solve_pose
from tracker.pose.inputs import outline_basis
from tracker.pose.refine import arc_correction
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
    # first order scales with sigma^2; the arc term (sigma^4) only adds to it
    diff = large.covariance - 16.0 * small.covariance
    assert np.all(np.linalg.eigvalsh(0.5 * (diff + diff.T)) > -1e-12)
    np.testing.assert_allclose(large.covariance[3:, 3:], 16.0 * small.covariance[3:, 3:])
    assert large.quality <= small.quality


def test_an_observations_own_corner_sigma_replaces_the_configured_one(
        camera: CameraModel) -> None:
    """A detector that knows its corners' sigma (a small plate's are less certain) passes
    it with the observation; the fix then is the one the solver would give at that sigma."""
    lms = wall()
    obs = see(lms, camera)
    assert all(o.corners_px is not None for o in obs)
    own = [replace(o, corner_sigma_px=2.0) for o in obs]
    by_obs = solve_pose(own, lms, camera, 0, config=PoseConfig(pixel_sigma_px=0.5))
    by_cfg = solve_pose(obs, lms, camera, 0, config=PoseConfig(pixel_sigma_px=2.0))
    assert isinstance(by_obs, PoseFix) and isinstance(by_cfg, PoseFix)
    np.testing.assert_allclose(by_obs.covariance, by_cfg.covariance, rtol=1e-9, atol=1e-15)
    bad = solve_pose([replace(obs[0], corner_sigma_px=-1.0), *obs[1:]], lms, camera, 0)
    assert isinstance(bad, NoFix) and "corner_sigma_px" in bad.reason


def test_a_plates_common_scale_error_is_in_its_covariance(camera: CameraModel) -> None:
    """Corners whose errors share a scale about the plate's centre (an outline drawn in or
    out as a whole, N(0, s) in the plate's width) besides independent noise: told so
    (``corner_scale_sigma_px``), one plate's fixes have NEES ~ chi-square(3); treated as
    independent they are overconfident along the line of sight.  0 changes nothing."""
    lms = wall()[:1]
    clean = see(lms, camera)[0]
    assert clean.corners_px is not None
    c = np.array(clean.corners_px)
    width = 0.5 * (np.linalg.norm(c[1] - c[0]) + np.linalg.norm(c[2] - c[3]))
    sigma, scale = 0.2, 0.6
    exact = AttitudeSample(0, *TRUE_RPY)
    rng = np.random.default_rng(11)
    told, untold = [], []
    for _ in range(200):
        att = _drawn_attitude(rng)
        eps = rng.normal(0.0, scale / width)
        noisy = c.mean(axis=0) + (1.0 + eps) * (c - c.mean(axis=0))
        noisy = noisy + rng.normal(0.0, sigma, c.shape)
        obs = replace(clean, corners_px=tuple((float(u), float(v)) for u, v in noisy),
                      corner_sigma_px=sigma)
        for out, extra in ((told, scale), (untold, None)):
            out.append(_position_nees(solve_pose(
                [replace(obs, corner_scale_sigma_px=extra)], lms, camera, 0, attitude=att)))
    nees, naive = np.array(told), np.array(untold)
    _assert_chi_square_3(nees)
    assert naive.mean() > 4.5  # without it the scale error is unaccounted for
    zero = solve_pose([replace(clean, corner_scale_sigma_px=0.0)], lms, camera, 0,
                      attitude=exact)
    none = solve_pose([clean], lms, camera, 0, attitude=exact)
    assert isinstance(zero, PoseFix) and isinstance(none, PoseFix)
    np.testing.assert_array_equal(zero.covariance, none.covariance)
    for bad in (-0.1, float("nan")):
        out = solve_pose([replace(clean, corner_scale_sigma_px=bad)], lms, camera, 0)
        assert isinstance(out, NoFix) and "corner_scale_sigma_px" in out.reason


def _position_nees(fix: PoseFix | NoFix) -> float:
    """The fix's position NEES against the truth (the fix must have come)."""
    assert isinstance(fix, PoseFix), getattr(fix, "reason", "")
    e = np.asarray(fix.position_ned_m) - TRUE_P
    return float(e @ np.linalg.solve(fix.covariance[:3, :3], e))


def _assert_chi_square_3(nees: np.ndarray) -> None:
    """200 draws of chi-square(3): mean 3 (+-0.6 covers 3.5 sigma), 95 % inside."""
    assert 2.4 < nees.mean() < 3.6
    assert np.mean((nees >= NEES_LOW_3DOF) & (nees <= NEES_HIGH_3DOF)) >= 0.9


def _outline_error(c: np.ndarray, amplitude: np.ndarray) -> np.ndarray:
    """Corner errors along a plate's outline modes: the last ``len(amplitude)`` of
    shift across, down, rotation, scale, aspect, shear, keystone across and along (unit
    8-vectors orthonormal to each other, ``outline_basis``)."""
    q = outline_basis(c)[:, 8 - len(amplitude):]
    return np.asarray((q @ amplitude).reshape(4, 2))


def test_plates_whose_corners_err_together_are_stated_so(camera: CameraModel) -> None:
    """Plates whose corners err along their outline's modes with other sigmas than the
    corners' (a shift and a scale larger, rotation, aspect and shear smaller): with
    ``corner_mode_sigma_rel`` saying so, the fixes of three plates have NEES ~
    chi-square(3); with the corners taken as independent they do not.  One plate alone
    keeps its corners' sigma in every mode (its own ``one_plate_*`` settings)."""
    lms = wall()[:3]
    clean = see(lms, camera)
    sigma = 0.1
    rel = np.array([1.5, 1.5, 0.3, 2.0, 0.3, 0.3, 0.5, 0.5])
    told_cfg = PoseConfig(corner_mode_sigma_rel=tuple(float(r) for r in rel))
    rng = np.random.default_rng(14)
    told, untold = [], []
    for _ in range(200):
        att = _drawn_attitude(rng)
        obs = []
        for o in clean:
            c = np.array(o.corners_px)
            noisy = c + _outline_error(c, rng.normal(0.0, rel * sigma))
            obs.append(replace(o, corners_px=tuple((float(u), float(v)) for u, v in noisy),
                               corner_sigma_px=sigma))
        for out, cfg in ((told, told_cfg), (untold, PoseConfig())):
            out.append(_position_nees(solve_pose(obs, lms, camera, 0, attitude=att,
                                                 config=cfg)))
    nees, naive = np.array(told), np.array(untold)
    _assert_chi_square_3(nees)
    assert naive.mean() > 4.5  # the shared shift and scale unaccounted for
    one = see(lms[:1], camera)
    alone = [solve_pose(one, lms[:1], camera, 0, attitude=AttitudeSample(0, *TRUE_RPY),
                        config=cfg) for cfg in (told_cfg, PoseConfig())]
    assert isinstance(alone[0], PoseFix) and isinstance(alone[1], PoseFix)
    np.testing.assert_array_equal(alone[0].covariance, alone[1].covariance)


def test_a_plate_states_its_own_modes(camera: CameraModel) -> None:
    """An observation's ``corner_mode_sigma_rel`` stands for the solver's for that plate:
    three plates telling theirs give the covariance the configuration gives; one plate
    telling others than its neighbours changes it."""
    lms = wall()[:3]
    obs = [replace(o, corner_sigma_px=0.1) for o in see(lms, camera)]
    rel = (1.5, 1.5, 0.3, 2.0, 0.3, 0.3, 0.5, 0.5)
    att = AttitudeSample(0, *TRUE_RPY)
    by_config = solve_pose(obs, lms, camera, 0, attitude=att,
                           config=PoseConfig(corner_mode_sigma_rel=rel))
    by_plates = solve_pose([replace(o, corner_mode_sigma_rel=rel) for o in obs], lms,
                           camera, 0, attitude=att)
    one_own = solve_pose([replace(obs[0], corner_mode_sigma_rel=(1.0,) * 8), *obs[1:]],
                         lms, camera, 0, attitude=att,
                         config=PoseConfig(corner_mode_sigma_rel=rel))
    assert isinstance(by_config, PoseFix) and isinstance(by_plates, PoseFix)
    assert isinstance(one_own, PoseFix)
    np.testing.assert_allclose(by_plates.covariance, by_config.covariance, rtol=1e-9)
    assert not np.allclose(one_own.covariance, by_config.covariance, rtol=1e-3)


def test_outline_modes_are_orthonormal_and_named_in_order() -> None:
    """The basis over a skewed quadrilateral's eight coordinates: orthonormal; its first
    two columns move every corner alike, the fourth along the corners' offsets."""
    c = np.array([[10.0, 20.0], [60.0, 25.0], [58.0, 70.0], [12.0, 64.0]])
    q = outline_basis(c)
    np.testing.assert_allclose(q.T @ q, np.eye(8), atol=1e-12)
    shift = q[:, 0].reshape(4, 2)
    np.testing.assert_allclose(shift, np.repeat(shift[:1], 4, axis=0), atol=1e-12)
    offsets = (c - c.mean(axis=0)).ravel()
    np.testing.assert_allclose(abs(q[:, 3] @ offsets), np.linalg.norm(offsets), rtol=1e-12)
    # Gram-Schmidt of the named modes in their order: q R = modes with R upper triangular
    named = (lambda x, y: (1.0, 0.0), lambda x, y: (0.0, 1.0), lambda x, y: (-y, x),
             lambda x, y: (x, y), lambda x, y: (x, -y), lambda x, y: (y, x),
             lambda x, y: (x * x, x * y), lambda x, y: (x * y, y * y))
    modes = np.column_stack([np.ravel([f(x, y) for x, y in c - c.mean(axis=0)])
                             for f in named])
    r = q.T @ modes
    np.testing.assert_allclose(q @ r, modes, atol=1e-9)
    np.testing.assert_allclose(np.tril(r, -1), 0.0, atol=1e-9)


def test_one_plates_outline_error_is_in_its_covariance(camera: CameraModel) -> None:
    """One plate whose outline errs as a whole (scale, aspect, shear, perspective, each
    N(0, (rel sigma)^2)) besides independent corner noise: with
    ``one_plate_outline_sigma_rel`` its fixes have NEES ~ chi-square(3); taken as
    independent they are overconfident.  Two plates are left as they were."""
    lms = wall()[:1]
    clean = see(lms, camera)[0]
    assert clean.corners_px is not None
    c = np.array(clean.corners_px)
    sigma, rel = 0.1, 4.0  # a 35 px plate: 0.4 px of outline error per mode
    told_cfg = PoseConfig(one_plate_outline_sigma_rel=rel)
    exact = AttitudeSample(0, *TRUE_RPY)
    rng = np.random.default_rng(12)
    told, untold = [], []
    for _ in range(200):
        att = _drawn_attitude(rng)
        noisy = c + _outline_error(c, rng.normal(0.0, rel * sigma, 5))
        noisy = noisy + rng.normal(0.0, sigma, c.shape)
        obs = replace(clean, corners_px=tuple((float(u), float(v)) for u, v in noisy),
                      corner_sigma_px=sigma)
        fix = solve_pose([obs], lms, camera, 0, attitude=att, config=told_cfg)
        assert isinstance(fix, PoseFix), getattr(fix, "reason", "")
        e = np.asarray(fix.position_ned_m) - TRUE_P
        told.append(float(e @ np.linalg.solve(fix.covariance[:3, :3], e)))
        naive = solve_pose([obs], lms, camera, 0, attitude=att)
        if isinstance(naive, PoseFix):  # else refused: "reprojection error N sigma"
            e = np.asarray(naive.position_ned_m) - TRUE_P
            untold.append(float(e @ np.linalg.solve(naive.covariance[:3, :3], e)))
    nees = np.array(told)
    assert 2.4 < nees.mean() < 3.6
    assert np.mean((nees >= NEES_LOW_3DOF) & (nees <= NEES_HIGH_3DOF)) >= 0.9
    # independent corners: the outline's error unaccounted for (or the plate refused)
    assert len(untold) < 180 or np.median(untold) > 2 * np.median(nees)
    two = wall()[:2]
    seen = see(two, camera)
    with_rel, without = (solve_pose(seen, two, camera, 0, attitude=exact, config=cfg)
                         for cfg in (told_cfg, PoseConfig()))
    assert isinstance(with_rel, PoseFix) and isinstance(without, PoseFix)
    np.testing.assert_array_equal(with_rel.covariance, without.covariance)


def test_one_plates_tilt_error_is_in_its_covariance(camera: CameraModel) -> None:
    """One plate whose keystone along its height errs (the square flight's wall-01: 7.7 x
    its corner sigma, docs/decisions.md "A lone plate's tilt"), the other outline modes
    not: with ``one_plate_tilt_sigma_rel`` its fixes have NEES ~ chi-square(3), without it
    they are overconfident; the other modes' sigma is ``one_plate_outline_sigma_rel``'s
    (so the tilt alone costs less than the whole outline at that sigma); two plates are
    left as they were."""
    lms = wall()[:1]
    clean = see(lms, camera)[0]
    assert clean.corners_px is not None
    c = np.array(clean.corners_px)
    sigma, rel = 0.1, 8.0
    cfgs = {"tilt": PoseConfig(one_plate_tilt_sigma_rel=rel), "naive": PoseConfig(),
            "outline": PoseConfig(one_plate_outline_sigma_rel=rel)}
    rng = np.random.default_rng(13)
    nees: dict[str, list[float]] = {k: [] for k in cfgs}
    trace: dict[str, list[float]] = {k: [] for k in cfgs}
    for _ in range(200):
        att = _drawn_attitude(rng)
        amplitude = np.zeros(5)
        amplitude[4] = rng.normal(0.0, rel * sigma)
        noisy = c + _outline_error(c, amplitude) + rng.normal(0.0, sigma, c.shape)
        obs = replace(clean, corners_px=tuple((float(u), float(v)) for u, v in noisy),
                      corner_sigma_px=sigma)
        for name, cfg in cfgs.items():
            fix = solve_pose([obs], lms, camera, 0, attitude=att, config=cfg)
            if name == "naive" and not isinstance(fix, PoseFix):
                continue  # refused: "reprojection error N sigma"
            assert isinstance(fix, PoseFix), getattr(fix, "reason", "")
            cov = fix.covariance[:3, :3]
            e = np.asarray(fix.position_ned_m) - TRUE_P
            nees[name].append(float(e @ np.linalg.solve(cov, e)))
            trace[name].append(float(np.trace(cov)))
    told = np.array(nees["tilt"])
    assert 2.4 < told.mean() < 3.6
    assert np.mean((told >= NEES_LOW_3DOF) & (told <= NEES_HIGH_3DOF)) >= 0.9
    # independent corners: the keystone's error unaccounted for (or the plate refused)
    assert len(nees["naive"]) < 180 or np.median(nees["naive"]) > 2 * np.median(told)
    assert np.median(trace["tilt"]) < np.median(trace["outline"])
    two = wall()[:2]
    seen = see(two, camera)
    exact = AttitudeSample(0, *TRUE_RPY)
    with_rel, without = (solve_pose(seen, two, camera, 0, attitude=exact, config=cfg)
                         for cfg in (cfgs["tilt"], PoseConfig()))
    assert isinstance(with_rel, PoseFix) and isinstance(without, PoseFix)
    np.testing.assert_array_equal(with_rel.covariance, without.covariance)


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


def test_arc_correction_adds_variance_along_the_line_of_sight_only() -> None:
    cov = np.diag([0.01, 0.64, 0.64, 1e-4, 1e-4, 1e-4])  # looking north, loose across
    pts = np.array([[20.0, -1.0, 0.0], [20.0, 1.0, 0.0]])
    out = arc_correction(cov, np.zeros(3), pts)
    extra = out - cov
    # 3/4 (0.64^2 + 0.64^2) / 20^2 along north, nothing else
    assert extra[0, 0] == pytest.approx(0.75 * 2 * 0.64**2 / 400.0)
    extra[0, 0] = 0.0
    np.testing.assert_allclose(extra, 0.0, atol=1e-15)
    tight = np.diag([1e-4, 1e-4, 1e-4, 1e-6, 1e-6, 1e-6])
    np.testing.assert_allclose(arc_correction(tight, np.zeros(3), pts), tight, rtol=1e-6)


def test_covariance_upper_triangle_is_row_major_for_mavlink(camera: CameraModel) -> None:
    lms = wall()
    fix = solve_pose(see(lms, camera), lms, camera, 0)
    assert isinstance(fix, PoseFix)
    urt = fix.covariance_urt
    c = fix.covariance
    assert len(urt) == 21
    # ArduPilot reads c0, c6, c11 (x y z) and c15, c18, c20 (roll pitch yaw)
    assert urt[0] == c[0, 0] and urt[5] == c[0, 5] and urt[6] == c[1, 1] and urt[11] == c[2, 2]
    assert urt[15] == c[3, 3] and urt[18] == c[4, 4] and urt[20] == c[5, 5]


def _drawn_attitude(rng: np.random.Generator) -> AttitudeSample:
    """The true attitude plus a draw of its own stated noise (roll/pitch, yaw sigmas)."""
    exact = AttitudeSample(0, *TRUE_RPY)
    sigma = [exact.roll_pitch_sigma_rad, exact.roll_pitch_sigma_rad, exact.yaw_sigma_rad]
    r, p, y = (float(v) for v in np.asarray(TRUE_RPY) + rng.normal(0.0, sigma))
    return replace(exact, roll_rad=r, pitch_rad=p, yaw_rad=y)
