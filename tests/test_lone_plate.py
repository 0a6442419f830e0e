"""A lone plate's fix is honest and follows the attitude prior's tilt (issue 19).

The square of ``--fly`` (config/scenarios/square.toml) starts hovering at (0, 0), where
wall-01 is the only plate in view and its tracked corners carry a 0.9 px keystone along
its height (docs/decisions.md, "A lone plate's tilt").  The attitude is off as the strict
fake autopilot's EKF is (1, -1, 3 deg) and stated at the deployment prior (2.5 / 5 deg).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from companion.settings import SIM_LAYERS, load_settings
from tests.test_perception import flight
from tracker.pose.types import PoseFix

ATTITUDE_ERROR_RAD = tuple(float(v) for v in np.deg2rad([1.0, -1.0, 3.0]))
NEES_95_3DOF = 7.815


def _hover_fixes(tilt_sigma_rel: float) -> list[tuple[float, float]]:
    """(error m, NEES) of every fix of the first 0.8 s, the simulator's layer with
    ``pose.one_plate_tilt_sigma_rel`` at ``tilt_sigma_rel``."""
    s = load_settings(shipped=SIM_LAYERS)
    pose = dataclasses.replace(s.pose, one_plate_tilt_sigma_rel=tilt_sigma_rel)
    _, _, out = flight("square", range(24), ATTITUDE_ERROR_RAD, pose_config=pose,
                       config=s.perception, acquire_config=s.acquire)
    got = []
    for result, _, state in out:
        fix = result.fix
        if isinstance(fix, PoseFix):
            assert fix.landmark_ids == ("wall-01",)
            e = np.subtract(fix.position_ned_m, state.position_ned_m)
            nees = float(e @ np.linalg.solve(np.asarray(fix.covariance)[:3, :3], e))
            got.append((float(np.linalg.norm(e)), nees))
    return got


def test_the_simulator_layer_declares_a_lone_plates_tilt() -> None:
    assert load_settings(shipped=SIM_LAYERS).pose.one_plate_tilt_sigma_rel == 8.0
    assert load_settings().pose.one_plate_tilt_sigma_rel == 0.0  # a real camera: not measured


def test_lone_plate_fix_is_honest_and_close() -> None:
    fixes = _hover_fixes(8.0)
    assert len(fixes) >= 18  # acquired within a few frames, then a fix per frame
    assert max(err for err, _ in fixes) < 0.25  # metres, at about 10 m
    assert all(nees < NEES_95_3DOF for _, nees in fixes)
    # the finding it fixes: the plate's own keystone, trusted, puts the fix 0.84 m off at a
    # stated 0.19 m
    undeclared = _hover_fixes(0.0)
    assert min(err for err, _ in undeclared) > 0.6
    assert min(nees for _, nees in undeclared) > 20.0
