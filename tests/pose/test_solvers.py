"""Initial solvers: bearing least squares and the landmark-pair consensus."""

from __future__ import annotations

import numpy as np

from tracker.pose.refine import RangePrior
from tracker.pose.solvers import bearing_consensus, bearing_least_squares


def _bearings(points: np.ndarray, p: np.ndarray) -> np.ndarray:
    rel = points - p
    return rel / np.linalg.norm(rel, axis=1, keepdims=True)


def test_bearing_least_squares_recovers_the_position_exactly() -> None:
    pts = np.array([[20.0, -5.0, -3.0], [18.0, 4.0, -6.0], [25.0, 1.0, -2.0]])
    p = np.array([1.0, 2.0, -4.0])
    est = bearing_least_squares(pts, _bearings(pts, p), np.eye(3))
    assert est is not None
    np.testing.assert_allclose(est, p, atol=1e-9)


def test_one_bearing_alone_does_not_fix_a_position() -> None:
    pts = np.array([[20.0, -5.0, -3.0]])
    assert bearing_least_squares(pts, _bearings(pts, np.zeros(3)), np.eye(3)) is None


def test_one_bearing_with_the_altitude_fixes_the_position() -> None:
    pts = np.array([[20.0, -5.0, -3.0]])
    p = np.array([1.0, 2.0, -4.0])
    est = bearing_least_squares(pts, _bearings(pts, p), np.eye(3), altitude_down_m=-4.0)
    assert est is not None
    np.testing.assert_allclose(est, p, atol=1e-9)


def test_one_bearing_with_a_laser_on_the_landmark_plane_fixes_the_position() -> None:
    pts = np.array([[20.0, -5.0, -3.0]])
    p = np.array([1.0, 2.0, -4.0])
    axis = np.array([1.0, 0.0, 0.0])  # body x = NED north at identity attitude
    # plane x = 20 facing the camera: the beam from p travels 19 m to meet it
    laser = RangePrior(19.0, 0.05, axis, pts[0], np.array([-1.0, 0.0, 0.0]))
    est = bearing_least_squares(pts, _bearings(pts, p), np.eye(3), range_prior=laser)
    assert est is not None
    np.testing.assert_allclose(est, p, atol=1e-9)


def test_consensus_singles_out_the_landmark_the_others_disagree_with() -> None:
    pts = np.array(
        [
            [20.0, -5.0, -3.0],
            [18.0, 4.0, -6.0],
            [25.0, 1.0, -2.0],
            [22.0, 8.0, -4.0],
            [30.0, -9.0, -7.0],
        ]
    )
    p = np.array([1.0, 2.0, -4.0])
    b = _bearings(pts, p)
    elsewhere = pts[3:4] + np.array([0.0, -9.0, 0.0])
    b[3] = _bearings(elsewhere, p)[0]  # landmark 3 seen somewhere else
    err = bearing_consensus(pts, b, np.arange(5, dtype=np.int64), threshold_rad=0.01)
    assert err is not None
    assert int(np.argmax(err)) == 3 and err[3] > 0.1
    assert np.all(np.delete(err, 3) < 1e-9)


def test_consensus_needs_three_landmarks() -> None:
    pts = np.array([[20.0, -5.0, -3.0], [18.0, 4.0, -6.0]])
    b = _bearings(pts, np.zeros(3))
    assert bearing_consensus(pts, b, np.arange(2, dtype=np.int64), 0.01) is None
