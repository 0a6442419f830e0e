"""A lone plate's corners less the steady error it showed beside other plates (issue 25).

A real crop's corners sit off in the same outline modes for hundreds of frames (low30's
real-03: rotation and scale 1-2 sigma). In a fix of several plates that error is outvoted
and shows in the plate's residual; alone, the plate's fix would carry it whole.
``CornerNoise.learn`` averages each track's residual along its outline's modes over fixes
of two or more plates (``corner_bias_fixes``) and ``CornerNoise.alone`` takes it off the
corners of a frame's only plate with corners (docs/decisions.md, "A lone plate's steady
corner error, learnt beside other plates").
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion.perception import Perception, PerceptionConfig
from companion.perception_types import Track
from tests.pose.conftest import TRUE_P, TRUE_RPY, wall
from tracker.camera import CameraModel
from tracker.pose.inputs import outline_basis
from tracker.pose.landmarks import landmark_corners_ned
from tracker.pose.solve import solve_pose
from tracker.pose.types import AttitudeSample, MapLandmark, Observation, PoseFix

CAMERA = CameraModel()
LANDMARKS = list(wall()[:2])  # two signs 20-24 m ahead, facing roughly south
POSITION, ATTITUDE = tuple(TRUE_P), TRUE_RPY
#: B's corners every frame: 2 % larger about their centre and turned 0.5 deg (px)
SCALE, TURN_RAD = 1.02, np.radians(0.5)


def true_corners(lm: MapLandmark) -> np.ndarray:
    return CAMERA.project_camera_points(CAMERA.world_to_camera(
        landmark_corners_ned(lm), np.asarray(POSITION), ATTITUDE))


def biased(corners: np.ndarray) -> np.ndarray:
    centre = corners.mean(axis=0)
    c, s = np.cos(TURN_RAD), np.sin(TURN_RAD)
    return centre + SCALE * (corners - centre) @ np.array([[c, s], [-s, c]])


def scene(bias_fixes: float) -> tuple[Perception, dict[str, Observation]]:
    plate = np.full((80, 120, 3), 128, np.uint8)
    plate[20:60, 30:90] = 20
    p = Perception(CAMERA, LANDMARKS, {"A": plate, "B": plate},
                   config=PerceptionConfig(corner_bias_fixes=bias_fixes))
    obs = {}
    for lm in LANDMARKS:
        seen = true_corners(lm)
        seen = biased(seen) if lm.landmark_id == "B" else seen
        p.trackset.live[lm.landmark_id] = Track(lm.landmark_id, None,  # type: ignore[arg-type]
                                         (0.0, 0.0, 10.0, 10.0), None, corners=seen)
        obs[lm.landmark_id] = Observation(
            centre_px=tuple(seen.mean(axis=0)), box_wh_px=(10.0, 10.0),
            landmark_id=lm.landmark_id, corner_sigma_px=0.2,
            corners_px=tuple((float(u), float(v)) for u, v in seen))
    return p, obs


def learn_beside(p: Perception, obs: dict[str, Observation], fixes: int) -> None:
    """``fixes`` fixes of both plates at the true pose."""
    fix = PoseFix(0, POSITION, ATTITUDE, np.eye(6), 90, ("A", "B"), "bearing_ls")
    for _ in range(fixes):
        p.noise.learn([obs["A"], obs["B"]], fix, p.tracks)


def test_a_plates_steady_error_is_learnt_in_its_modes_beside_another_plate() -> None:
    p, obs = scene(60)
    learn_beside(p, obs, 40)
    b = np.asarray(obs["B"].corners_px)
    expected = outline_basis(b).T @ (b - true_corners(LANDMARKS[1])).ravel()
    assert p.tracks["B"].bias_fixes == 40
    assert p.tracks["B"].bias_modes == pytest.approx(expected, abs=1e-9)
    assert abs(expected[3]) > 0.5 and abs(expected[2]) > 0.2  # scale and rotation, px
    assert p.tracks["A"].bias_modes == pytest.approx(np.zeros(8), abs=1e-9)
    # a fix of one plate teaches nothing
    one = PoseFix(0, POSITION, ATTITUDE, np.eye(6), 90, ("B",), "ippe")
    p.noise.learn([obs["B"]], one, p.tracks)
    assert p.tracks["B"].bias_fixes == 40


def test_only_a_lone_plate_has_its_learnt_error_taken_off() -> None:
    p, obs = scene(60)
    learn_beside(p, obs, 29)  # under half of 60: not used yet
    assert p.noise.alone([obs["B"]], p.tracks) == [obs["B"]]
    learn_beside(p, obs, 1)
    (alone,) = p.noise.alone([obs["B"]], p.tracks)
    assert np.asarray(alone.corners_px) == pytest.approx(true_corners(LANDMARKS[1]), abs=1e-9)
    assert alone.corner_sigma_px == obs["B"].corner_sigma_px  # the statement is unchanged
    # beside another plate with corners, or a box-only one: as measured, or corrected
    both = [obs["A"], obs["B"]]
    assert p.noise.alone(both, p.tracks) == both
    box_only = dataclasses.replace(obs["A"], corners_px=None, corner_sigma_px=None)
    assert p.noise.alone([box_only, obs["B"]], p.tracks)[1] == alone


def test_the_lone_plates_fix_is_where_the_plates_together_put_it() -> None:
    """The solver on B alone (with the autopilot's attitude, true, at its default 2.5 /
    5 deg): its biased corners put the vehicle centimetres off; less the learnt error, on
    the truth."""
    p, obs = scene(60)
    learn_beside(p, obs, 40)
    errors = []
    for seen in ([obs["B"]], p.noise.alone([obs["B"]], p.tracks)):
        fix = solve_pose(seen, LANDMARKS, CAMERA, 0, attitude=AttitudeSample(0, *ATTITUDE))
        assert isinstance(fix, PoseFix), fix
        errors.append(float(np.linalg.norm(np.subtract(fix.position_ned_m, POSITION))))
    assert errors[0] > 0.1 and errors[1] < 1e-3, errors


def test_off_learns_nothing_and_changes_nothing() -> None:
    p, obs = scene(0)
    learn_beside(p, obs, 40)
    assert p.tracks["B"].bias_modes is None
    assert p.noise.alone([obs["B"]], p.tracks) == [obs["B"]]
